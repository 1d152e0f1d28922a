// licvdb: bake 3D line integral convolution of vector fields into OpenVDB volumes.
//
// Subcommands: field, bake, info, help, version. Only main() catches: lic::InputError and usage
// errors exit 2, other failures exit 1. Progress goes to stderr when it is a terminal; --json
// puts a machine-readable summary on stdout.

#include "vdbexport/bake/Bake.h"
#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/bake/Distributed.h"
#include "vdbexport/io/Info.h"
#include "vdbexport/io/Numbers.h"
#include "vdbexport/bake/Recipe.h"
#include "vdbexport/render/Render.h"
#include "vdbexport/cli/TerminalProgress.h"
#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/VdbIO.h"

#include "lic/util/Error.h"
#include "lic/field/Presets.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <new>
#include <sstream>

namespace {

vdbexport::TerminalProgress* gProgress = nullptr;

extern "C" void onInterrupt(int)
{
    if (gProgress) gProgress->requestCancel();
}

/// Ends the progress line and clears gProgress when the scope of the TerminalProgress it points
/// to is left, also by an exception (the catch handlers in main() run after that scope is gone).
struct ProgressGuard
{
    ProgressGuard() = default;
    ProgressGuard(const ProgressGuard&) = delete;
    ProgressGuard& operator=(const ProgressGuard&) = delete;
    ~ProgressGuard()
    {
        if (gProgress) gProgress->finishLine();
        gProgress = nullptr;
    }
};

struct Common
{
    bool quiet = false;
    bool json = false;
    int threads = 0;
    std::string progress = "bar";

    vdbexport::TerminalProgress::Style progressStyle() const
    {
        return progress == "lines" ? vdbexport::TerminalProgress::Style::Lines : vdbexport::TerminalProgress::Style::Bar;
    }
};

void addCommon(CLI::App* cmd, Common& c)
{
    cmd->add_option("--progress", c.progress,
                    "bar: a progress bar when stderr is a terminal; lines: one `progress FRACTION STAGE` "
                    "line per update on stderr, for programs [bar]")
        ->check(CLI::IsMember({"bar", "lines"}));
    cmd->add_flag("-q,--quiet", c.quiet, "No progress or messages on stderr");
    cmd->add_flag("--json", c.json, "Print a machine-readable JSON summary on stdout");
    cmd->add_option("--threads", c.threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024));
}

openvdb::Coord parseRes(const std::string& s)
{
    std::vector<int> v;
    std::stringstream in(s);
    std::string part;
    while (std::getline(in, part, ',')) {
        try {
            std::size_t used = 0;
            v.push_back(std::stoi(part, &used));
            if (used != part.size()) throw std::invalid_argument(part);
        } catch (const std::exception&) {
            throw lic::InputError("--res \"" + s + "\" is not a resolution; expected X,Y,Z (e.g. 64,64,64) or one number");
        }
    }
    if (v.size() == 1) return openvdb::Coord(v[0]);
    if (v.size() != 3) throw lic::InputError("--res \"" + s + "\" needs 1 or 3 numbers (X,Y,Z)");
    return openvdb::Coord(v[0], v[1], v[2]);
}

bool inReadChild()
{
    const char* v = std::getenv("LICVDB_READ_CHILD");
    return v && std::string(v) == "1";
}

/// This program's path (/proc/self/exe), "" if it cannot be found.
std::string selfExecutable()
{
    std::error_code ec;
    const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
    return ec ? std::string() : p.string();
}

std::string presetList()
{
    std::string out;
    for (const auto& name : lic::presetNames())
        out += "  " + name + std::string(name.size() < 12 ? 12 - name.size() : 1, ' ') +
               lic::presetDescription(name) + "\n";
    return out;
}

/// `licvdb info --check FILE`: layers 1 and 2 (docs/inputs.md); in the child that layer 2 starts
/// (LICVDB_READ_CHILD=1), layer 1 and then a full read and description of every grid in-process.
int checkCommand(const std::string& path, const Common& common)
{
    nlohmann::json out{{"path", path}};
    try {
        const vdbexport::VdbCheckResult r = vdbexport::detail::checkedVdb(path);
        if (inReadChild()) (void)vdbexport::describeVdb(path);
        out["ok"] = true;
        out["file_version"] = r.fileVersion;
        out["grids"] = nlohmann::json::array();
        std::string list;
        for (const auto& g : r.grids) {
            nlohmann::json j{{"name", g.name}, {"grid_type", g.gridType}, {"value_type", g.valueType},
                             {"half_float", g.halfFloat}, {"compression", g.compression}, {"tiles", g.tiles},
                             {"internal_nodes", g.internalNodes}, {"leaves", g.leaves}};
            if (g.instance) j["instance_of"] = g.instanceParent;
            if (!g.skipReason.empty()) j["skipped"] = g.skipReason;
            out["grids"].push_back(j);
            list += (list.empty() ? "" : ", ") + g.name + " (" + (g.valueType.empty() ? g.gridType : g.valueType) + ")";
        }
        if (common.json) std::cout << out.dump(2) << "\n";
        else if (!common.quiet) std::cout << path << ": intact (" << r.grids.size() << " grid" << (r.grids.size() == 1 ? "" : "s")
                                          << (list.empty() ? "" : ": " + list) << ")\n";
        return 0;
    } catch (const lic::InputError& e) {
        if (common.json) {
            out["ok"] = false;
            out["error"] = e.what();
            std::cout << out.dump(2) << "\n";
        }
        throw;
    }
}

} // namespace

int main(int argc, char** argv)
{
    // Layer 2 of the .vdb read defences: every read first runs in a child `licvdb info --check`.
    if (!inReadChild()) vdbexport::setReadIsolation(selfExecutable());

    CLI::App app{"licvdb: 3D line integral convolution of vector fields, baked into OpenVDB volumes"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("licvdb ") + LICVDB_VERSION);
    app.footer("Run `licvdb help CMD` for a command's options and examples.");
    std::string currentCommand = "licvdb";
    // A distributed bake under mpirun/srun; started only for `bake` (see vdbexport/bake/Distributed.h).
    vdbexport::MpiSession mpi;

    // field ------------------------------------------------------------------------------------
    Common fieldCommon;
    std::string preset, res, fieldOut;
    CLI::App* field = app.add_subcommand("field", "Write an analytic example vector field");
    field->add_option("preset", preset, "Preset name")->required();
    field->add_option("--res", res, "Resolution X,Y,Z in voxels (default per preset)");
    field->add_option("-o,--out", fieldOut, "Output .vdb (with --frames: a pattern with #### for the frame number)")->required();
    std::string fieldFrames;
    double fieldFps = 24;
    field->add_option("--frames", fieldFrames, "FIRST,LAST: write a sequence, frame n at time n/fps (tornado moves; the others are steady)");
    field->add_option("--fps", fieldFps, "With --frames: frames per time unit of the field [24]");
    addCommon(field, fieldCommon);
    field->footer("Presets:\n" + presetList() +
                  "\nExamples:\n  licvdb field abc --res 64,64,64 --out abc.vdb\n"
                  "  licvdb field tabbed-jet --out jet.vdb      # 101x101x148, with `temperature`\n"
                  "  licvdb field tornado --frames 1,48 --out tornado_####.vdb   # an unsteady sequence\n");

    // bake -------------------------------------------------------------------------------------
    Common bakeCommon;
    std::string recipePath;
    vdbexport::Recipe cli; // values of flags that were given
    CLI::App* bake = app.add_subcommand("bake", "Bake a LIC volume from a vector field");
    bake->add_option("-f,--field", cli.field.path, "Field: .vdb (a Vec3 grid, or vel.x/.y/.z), .npy, .vti, .vtk or raw (with --shape)");
    bake->add_option("--grid", cli.field.grid, "Vector grid name (default: velocity, vel, v, the only Vec3 grid)");
    bake->add_option("-o,--out", cli.output.path, "Output .vdb (a sidecar manifest OUT.licvdb.json is written too)");
    bake->add_option("-r,--recipe", recipePath, "JSON recipe; flags override its values");
    auto* oInput = bake->add_option("--input", cli.input.type, "Input texture: noise|spots [noise]");
    auto* oFilter = bake->add_option("--noise-filter", cli.input.noiseFilter, "Noise reconstruction: binomial|none [binomial]");
    auto* oEngine = bake->add_option("--engine", cli.lic.engine, "auto|naive|fast|splat: auto = splat for spots, fast for noise [auto]");
    auto* oKernel = bake->add_option("--kernel", cli.lic.kernel, "box|exp (oriented streamlets, bright head downstream) [box]");
    auto* oDecay = bake->add_option("--decay", cli.lic.decay, "exp kernel: weight ratio of consecutive samples, (0,1) [0.9]");
    auto* oLength = bake->add_option("--length", cli.lic.length, "Kernel half-length, output voxels [20]");
    auto* oStep = bake->add_option("--step", cli.lic.step, "Sample spacing along streamlines, output voxels [0.5]");
    auto* oIntegrator = bake->add_option("--integrator", cli.lic.integrator, "rk4|rk45 [rk4]");
    auto* oTolerance = bake->add_option("--tolerance", cli.lic.tolerance, "rk45 local error, output voxels [1e-3]");
    auto* oMinHits = bake->add_option("--min-hits", cli.lic.minHits, "fast: deposits a voxel needs before it stops seeding [2]");
    auto* oBrick = bake->add_option("--brick", cli.lic.brick,
                                    "Brick edge, output voxels: a multiple of 8 in 8..512, or 0 = automatic [0]");
    auto* oUpsample = bake->add_option("--upsample", cli.output.upsample, "Output voxels per field voxel [2]");
    auto* oSeed = bake->add_option("--seed", cli.input.seed, "Hash seed of the noise and of the spot positions [1]");
    auto* oContrast = bake->add_option("--contrast", cli.output.contrast, "stretch|none [stretch]");
    std::string colorScalar, colormap;
    bake->add_option("--color", colorScalar,
                     "Colour by a scalar: speed, vorticity, streamwise-vorticity, helicity, q-criterion, lambda2, or a float grid of the field file; NAME-abs = |NAME|, NAME-gradient = |grad NAME|");
    auto* oColormap = bake->add_option("--colormap", colormap,
                                       "heated-object|red-yellow|grey-purple|viridis|magma|inferno|cividis|coolwarm or a value,r,g,b .csv [viridis]");
    std::string fieldOrigin, fieldShape, fieldCrop;
    double fieldVoxelSize = 0, fieldResample = 0;
    auto* oFormat = bake->add_option("--format", cli.field.format, "Field format: auto|vdb|npy|vti|vtk|raw [auto: by extension]");
    auto* oVoxelSize = bake->add_option("--voxel-size", fieldVoxelSize, "Dense inputs (npy, raw, vti, vtk): world units per voxel [file's, else 1]");
    bake->add_option("--origin", fieldOrigin, "Dense inputs: world position X,Y,Z of voxel (0,0,0)'s centre [file's, else 0]");
    bake->add_option("--shape", fieldShape, "Raw input: X,Y,Z voxels (data is X,Y,Z,3 in C order)");
    auto* oDtype = bake->add_option("--dtype", cli.field.dtype, "Raw input: float32|float64|f4|f8|<f4|>f4|<f8|>f8 [float32]");
    auto* oResample = bake->add_option("--resample", fieldResample, "Resample the field to this voxel size, world units");
    bake->add_option("--crop", fieldCrop, "Crop the field to world box X0,Y0,Z0,X1,Y1,Z1");
    auto* oMask = bake->add_option("--mask", cli.field.mask, "none|zero: zero deactivates zero-velocity voxels [none]");
    auto* oNanPolicy = bake->add_option("--nan-policy", cli.field.nanPolicy, "refuse|zero: NaN/Inf in the field is an error, or set to 0 [refuse]");
    auto* oFrames = bake->add_option("--frames", cli.animation.frames, "Frames of a cyclic animation [1]");
    std::string fieldFramesRange;
    auto* oFieldFrames = bake->add_option("--field-frames", fieldFramesRange,
                                          "FIRST,LAST: bake the unsteady sequence --field pattern_####.vdb (default: every frame on disk)");
    auto* oFps = bake->add_option("--fps", cli.field.fps, "Unsteady sequence: frames per second (velocity is world units per second) [24]");
    bool writeInput = false, writeTangent = false, halfFloat = false;
    auto* oWriteInput = bake->add_flag("--write-input", writeInput, "Also write the input texture as grid `input`");
    auto* oWriteTangent = bake->add_flag("--write-tangent", writeTangent, "Also write the unit flow direction as vec3s grid `tangent`");
    auto* oHalf = bake->add_flag("--half", halfFloat, "Store grids as 16-bit half floats on disk (about half the file size)");
    // Spots, halos, width, region and surface of interest.
    std::string spotRadii, roiScalar, roiRange, roiMode, widthScalar, widthRange, surfaceScalar;
    double surfaceThreshold = 0.0;
    bool writeSeries = false, widthInvert = false;
    auto* oDistribution = bake->add_option("--distribution", cli.input.distribution, "Spots: regular|random|jittered|poisson [poisson]");
    auto* oSpacing = bake->add_option("--spacing", cli.input.spacing, "Spots: spacing d between spot centres, output voxels [6]");
    auto* oJitter = bake->add_option("--jitter", cli.input.jitter, "Jittered spots: offset up to ±jitter·d/2 per axis, [0,1] [0.25]");
    bake->add_option("--radii", spotRadii, "Spots: line radii R1,R2,... increasing, output voxels (one per width level, at most 4) [1]");
    auto* oHaloScale = bake->add_option("--halo-scale", cli.input.haloScale, "Spots: halo radius / line radius, >= 1 [2]");
    bake->add_option("--surface", surfaceScalar, "Spots on the ridge surface of a scalar (e.g. speed-gradient = |grad speed|)");
    auto* oSurfaceThreshold = bake->add_option("--surface-threshold", surfaceThreshold, "--surface: ridge points need scalar > this [0]");
    bake->add_option("--roi", roiScalar, "Region of interest by a scalar (speed, vorticity, a float grid, NAME-gradient, NAME-abs)");
    bake->add_option("--roi-range", roiRange, "--roi: kept range LO,HI in the scalar's units");
    auto* oRoiMode = bake->add_option("--roi-mode", roiMode, "--roi: pre (mask the input; lines leave along the flow) | post (mask the output) [pre]");
    bake->add_option("--width", widthScalar, "Spots: pick the width level per voxel by a scalar (needs 2+ radii)");
    bake->add_option("--width-range", widthRange, "--width: scalar range LO,HI mapped onto narrowest..widest [auto: 1st-99th percentile]");
    bake->add_flag("--width-invert", widthInvert, "--width: high scalar = thin lines (the seed shows slow flow wide)");
    bake->add_flag("--write-series", writeSeries, "Spots: also write density_w<k> and halo_w<k> for every width level");
    addCommon(bake, bakeCommon);
    bake->footer(
        "Lengths are in output voxels (field voxel size / upsample).\n\n"
        "Examples:\n"
        "  licvdb field tabbed-jet --out jet.vdb\n"
        "  licvdb bake --field jet.vdb --out jet_lic.vdb\n"
        "  licvdb bake --field abc.vdb --out abc_lic.vdb --length 40 --step 0.5 --json\n"
        "  licvdb bake --recipe examples/recipes/tabbed-jet-halos.json --field jet.vdb --out jet_halos.vdb\n"
        "  licvdb bake --field jet.vdb --out jet_vort.vdb --color vorticity --colormap heated-object\n"
        "  licvdb bake --field cache_data/fluid_data_0010.vdb --out smoke_lic.vdb   # Blender smoke cache\n"
        "  licvdb bake --field 'cache_data/fluid_data_####.vdb' --field-frames 1,120 --out smoke.vdb  # unsteady: smoke_0001.vdb …\n"
        "  licvdb bake --field jet.vdb --out oriented.vdb --kernel exp --frames 24   # a loop of tapered streamlets\n"
        "  licvdb bake --field flow.npy --voxel-size 0.1 --origin -1,-1,0 --out flow_lic.vdb\n"
        "  licvdb bake --field flow.raw --shape 64,64,32 --dtype float64 --out flow_lic.vdb\n"
        "Field formats and preparation: see docs/inputs.md.\n");

    // info -------------------------------------------------------------------------------------
    Common infoCommon;
    std::string infoPath;
    bool infoCheck = false;
    CLI::App* info = app.add_subcommand("info", "List the grids, bounding boxes and metadata of a .vdb");
    info->add_option("file", infoPath, "A .vdb file")->required();
    info->add_flag("--check", infoCheck,
                   "Only check that the file is intact: exit 0 if it is, 2 with the reason if it is not");
    addCommon(info, infoCommon);
    info->footer("--check walks the file's whole structure (every size and offset it stores, every leaf\n"
                 "buffer decoded), then reads every grid with OpenVDB in a child process, so a file that would\n"
                 "crash or hang a reader is refused with exit 2 instead. Every licvdb command that reads a\n"
                 ".vdb (bake, render, info) does the same first; see docs/inputs.md.\n\n"
                 "Examples:\n  licvdb info jet_lic.vdb\n  licvdb info jet_lic.vdb --json | python3 -m json.tool\n"
                 "  licvdb info --check download.vdb && echo intact\n"
                 "  licvdb info --check download.vdb --json     # {\"ok\": false, \"error\": \"...\"} on stdout too\n");

    // render -----------------------------------------------------------------------------------
    Common renderCommon;
    vdbexport::RenderJob rjob;
    vdbexport::RenderFlagStrings rflags;
    double rAzimuth = 0, rElevation = 0, rDistance = 0, rEyeSep = 0;
    CLI::App* render = app.add_subcommand("render", "Raycast a baked .vdb to an image (reference halo renderer)");
    render->add_option("input", rjob.input, "Baked .vdb (a `density` grid), first frame OUT_0001.vdb, or a bake's manifest OUT.licvdb.json")->required();
    render->add_option("-o,--out", rjob.output, "Image: .png/.jpg/.tif (display, via OCIO), .exr (scene-linear), .gif")->required();
    render->add_option("--size", rflags.size, "Image size W,H in pixels [1024,1024]");
    render->add_option("--view", rflags.view, "front|back|left|right|top|bottom (Blender's, Z up) [front]");
    render->add_flag("--ortho", rjob.camera.orthographic, "Orthographic camera (default perspective)");
    auto* oAz = render->add_option("--azimuth", rAzimuth, "Degrees about +Z from the front view (90 = right view); overrides --view's");
    auto* oEl = render->add_option("--elevation", rElevation, "Degrees above the horizon (90 = top view); overrides --view's");
    auto* oDist = render->add_option("--distance", rDistance, "Camera distance from the bbox centre, world units [fit]");
    render->add_option("--fov", rjob.camera.fovY, "Vertical field of view, degrees [30]");
    render->add_option("--halos", rflags.halos, "on|off: halo compositing when the file has a `halo` grid [on]");
    render->add_option("--halo-strength", rjob.settings.haloStrength, "Opacity added at a halo exit per unit of its max halo [1]");
    render->add_option("--halo-threshold", rjob.settings.haloThreshold, "A ray is inside a halo where halo > this [0.05]");
    render->add_option("--density-scale", rjob.settings.densityScale, "Extinction per unit density per voxel length [auto: 2 with a halo grid, else fit]");
    render->add_option("--density-range", rflags.densityRange, "LO,HI transfer window on density [0,1]");
    render->add_option("--brightness", rjob.settings.brightness, "Emission multiplier [1]");
    render->add_option("--step", rjob.settings.step, "Ray step, voxels [0.5]");
    bool rNoSkip = false;
    render->add_flag("--no-skipping", rNoSkip, "Diagnostic: march empty 8^3 bricks too (same image, slower)");
    render->add_option("--colormap", rjob.colormap, "Colour by the `scalar` grid: a colormap name or value,r,g,b .csv");
    render->add_option("--field", rjob.field, "Velocity .vdb: line tangents for lighting when there is no `tangent` grid");
    render->add_option("--light", rflags.light, "headlight | X,Y,Z (direction towards the light) | off [headlight]");
    render->add_option("--stereo", rflags.stereo, "sbs (side by side, 2W wide) | anaglyph (red-cyan)");
    auto* oEye = render->add_option("--eye-separation", rEyeSep, "Stereo eye distance, world units [distance/30]");
    render->add_option("--frames", rjob.frames, "Render the sequence IN_0001.vdb … IN_000N.vdb to IMAGE_0001 …");
    render->add_flag("--gif", rjob.gif, "With a sequence, also write an animated IMAGE.gif");
    render->add_option("--fps", rjob.fps, "GIF frame rate [12]");
    render->add_option("--view-transform", rjob.viewTransform, "standard|filmic|raw (OCIO view for .png/.jpg/.tif/.gif) [standard]");
    render->add_option("--ocio-config", rjob.ocioConfig, "OCIO config [$LICVDB_OCIO_CONFIG, else the shipped one]");
    addCommon(render, renderCommon);
    render->footer(
        "Examples:\n"
        "  licvdb render jet_lic.vdb --out jet.png\n"
        "  licvdb render jet_lic.vdb --out jet.exr --view right --elevation 20 --size 1920,1080\n"
        "  licvdb render jet_lic.vdb --out jet.png --density-range 0.6,1 --view-transform filmic\n"
        "  licvdb render jet_lic.vdb --out jet_sbs.png --stereo sbs\n"
        "  licvdb render loop_0001.vdb --frames 24 --out loop.png --gif     # loop_0001.png … + loop.gif\n"
        "See docs/render.md for the algorithm, the transfer function and the --json camera.\n");

    // help / version ---------------------------------------------------------------------------
    std::string helpTopic;
    CLI::App* help = app.add_subcommand("help", "Show help for a command");
    help->add_option("command", helpTopic, "field, bake, render, info");
    app.add_subcommand("version", "Print the version");

    // The program's own synopsis (App::help() would describe the parsed subcommand instead).
    const auto synopsis = [&app] { return app.get_formatter()->make_help(&app, app.get_name().empty() ? "licvdb" : app.get_name(), CLI::AppFormatMode::Normal); };
    if (argc < 2) { // no command at all: say what there is, not only that something is missing
        std::cerr << synopsis();
        return 2;
    }
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) { // also --help and --version, which exit 0
        const int code = app.exit(e);
        if (code != 0) std::cerr << "see `licvdb help` or `licvdb help COMMAND`\n";
        return code == 0 ? 0 : 2;
    }

    try {
        if (help->parsed()) {
            if (helpTopic.empty()) {
                std::cout << synopsis();
                return 0;
            }
            CLI::App* sub = nullptr;
            try {
                sub = app.get_subcommand(helpTopic);
            } catch (const CLI::OptionNotFound&) {
            }
            if (!sub) throw lic::InputError("no command \"" + helpTopic + "\"; expected field, bake, render or info");
            std::cout << sub->help();
            return 0;
        }
        if (app.got_subcommand("version")) {
            std::cout << "licvdb " << LICVDB_VERSION << "\n";
            return 0;
        }

        if (field->parsed()) {
            currentCommand = "licvdb field";
            const openvdb::Coord r = res.empty() ? lic::presetDefaultResolution(preset) : parseRes(res);
            std::vector<int> numbers{0};
            if (!fieldFrames.empty()) {
                const auto [firstFrame, lastFrame] = vdbexport::parseFrameRange("--frames", fieldFrames);
                if (!(fieldFps > 0) || !std::isfinite(fieldFps)) throw lic::InputError("--fps must be > 0");
                if (!vdbexport::isFramePattern(fieldOut))
                    throw lic::InputError("--out \"" + fieldOut + "\": with --frames, put #### where the frame number goes");
                numbers.clear();
                for (int n = firstFrame; n <= lastFrame; ++n) numbers.push_back(n);
            }
            vdbexport::OutputSet outputs; // all frames appear together, or none
            openvdb::GridPtrVec grids;
            std::vector<std::string> written;
            for (int n : numbers) {
                const double time = fieldFrames.empty() ? 0.0 : double(n) / fieldFps;
                const lic::PresetField f = lic::makePresetField(preset, r, time);
                grids = {f.velocity};
                for (const auto& s : f.scalars) grids.push_back(s);
                written.push_back(fieldFrames.empty() ? fieldOut : vdbexport::expandFramePattern(fieldOut, n));
                outputs.addVdb(written.back(), grids);
            }
            outputs.commit();
            if (fieldCommon.json) {
                nlohmann::json j{{"output", fieldOut}, {"preset", preset}, {"resolution", {r[0], r[1], r[2]}},
                                 {"grids", nlohmann::json::array()}, {"files", written}};
                for (const auto& g : grids) j["grids"].push_back(g->getName());
                std::cout << j.dump(2) << "\n";
            } else if (!fieldCommon.quiet) {
                std::cerr << "wrote " << preset << " field " << r[0] << "x" << r[1] << "x" << r[2] << " to " << fieldOut
                          << "\n";
            }
            return 0;
        }

        if (render->parsed()) {
            currentCommand = "licvdb render";
            vdbexport::applyRenderFlags(rjob, rflags);
            if (oAz->count()) rjob.azimuth = rAzimuth;
            if (oEl->count()) rjob.elevation = rElevation;
            if (oDist->count()) rjob.camera.distance = rDistance;
            if (oEye->count()) rjob.eyeSeparation = rEyeSep;
            rjob.settings.threads = renderCommon.threads;
            rjob.settings.emptySpaceSkipping = !rNoSkip;
            vdbexport::TerminalProgress progress(renderCommon.quiet, stderr, false, renderCommon.progressStyle());
            gProgress = &progress;
            const ProgressGuard progressGuard; // declared after `progress`, so destroyed first
            std::signal(SIGINT, onInterrupt);
            const nlohmann::json summary = vdbexport::render(rjob, progress);
            progress.finishLine();
            gProgress = nullptr;
            if (renderCommon.json) {
                std::cout << summary.dump(2) << "\n";
            } else if (!renderCommon.quiet) {
                for (const auto& f : summary["files"]) std::fprintf(stderr, "wrote %s\n", f.get<std::string>().c_str());
                std::fprintf(stderr, "rendered %d frame(s) in %.2f s\n", summary["frames"].get<int>(),
                             summary["seconds"]["render"].get<double>());
            }
            return 0;
        }

        if (info->parsed()) {
            currentCommand = "licvdb info";
            if (infoCheck) return checkCommand(infoPath, infoCommon);
            const nlohmann::json d = vdbexport::describeVdb(infoPath);
            std::cout << (infoCommon.json ? d.dump(2) + "\n" : vdbexport::formatInfo(d));
            return 0;
        }

        if (bake->parsed()) {
            currentCommand = "licvdb bake";
            vdbexport::Recipe r = recipePath.empty() ? vdbexport::Recipe{} : vdbexport::loadRecipeFile(recipePath);
            // Flags override the recipe.
            if (!cli.field.path.empty()) r.field.path = cli.field.path;
            if (!cli.field.grid.empty()) r.field.grid = cli.field.grid;
            if (!cli.output.path.empty()) r.output.path = cli.output.path;
            if (oFormat->count()) r.field.format = cli.field.format;
            if (oVoxelSize->count()) r.field.voxelSize = fieldVoxelSize;
            if (oDtype->count()) r.field.dtype = cli.field.dtype;
            if (oResample->count()) r.field.resample = fieldResample;
            if (oMask->count()) r.field.mask = cli.field.mask;
            if (oNanPolicy->count()) r.field.nanPolicy = cli.field.nanPolicy;
            if (!fieldOrigin.empty()) {
                const auto v = vdbexport::parseNumberList("--origin", fieldOrigin, "X,Y,Z", 3);
                r.field.origin = std::array<double, 3>{v[0], v[1], v[2]};
            }
            if (!fieldShape.empty()) {
                const auto v = vdbexport::parseNumberList("--shape", fieldShape, "X,Y,Z (voxels)", 3);
                r.field.shape = std::array<double, 3>{v[0], v[1], v[2]};
            }
            if (!fieldCrop.empty()) {
                const auto v = vdbexport::parseNumberList("--crop", fieldCrop, "X0,Y0,Z0,X1,Y1,Z1 (world units)", 6);
                r.field.crop = std::array<std::array<double, 3>, 2>{{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}}};
            }
            if (oInput->count()) r.input.type = cli.input.type;
            if (oFilter->count()) r.input.noiseFilter = cli.input.noiseFilter;
            if (oEngine->count()) r.lic.engine = cli.lic.engine;
            if (oKernel->count()) r.lic.kernel = cli.lic.kernel;
            if (oDecay->count()) r.lic.decay = cli.lic.decay;
            if (oLength->count()) r.lic.length = cli.lic.length;
            if (oStep->count()) r.lic.step = cli.lic.step;
            if (oIntegrator->count()) r.lic.integrator = cli.lic.integrator;
            if (oTolerance->count()) r.lic.tolerance = cli.lic.tolerance;
            if (oUpsample->count()) r.output.upsample = cli.output.upsample;
            if (oMinHits->count()) r.lic.minHits = cli.lic.minHits;
            if (oBrick->count()) r.lic.brick = cli.lic.brick;
            if (oSeed->count()) r.input.seed = cli.input.seed;
            if (oContrast->count()) r.output.contrast = cli.output.contrast;
            if (oFrames->count()) r.animation.frames = cli.animation.frames;
            if (oFieldFrames->count()) {
                r.field.frames = vdbexport::parseFrameRange("--field-frames", fieldFramesRange);
                if (!vdbexport::isFramePattern(r.field.path)) {
                    throw lic::InputError("--field \"" + r.field.path + "\" has no frame number: with --field-frames, put a run "
                                          "of # (or %04d) where it goes, e.g. cache/data/fluid_data_####.vdb");
                }
            }
            if (oFps->count()) r.field.fps = cli.field.fps;
            if (!colorScalar.empty()) {
                if (!r.color) r.color = vdbexport::ColorSpec{};
                r.color->scalar = colorScalar;
            }
            if (oColormap->count()) {
                if (!r.color) throw lic::InputError("--colormap needs a colour scalar: add --color SCALAR");
                r.color->colormap = colormap;
            }
            if (oWriteInput->count()) r.output.writeInput = true;
            if (oWriteTangent->count()) r.output.writeTangent = true;
            if (oHalf->count()) r.output.half = true;
            if (oDistribution->count()) r.input.distribution = cli.input.distribution;
            if (oSpacing->count()) r.input.spacing = cli.input.spacing;
            if (oJitter->count()) r.input.jitter = cli.input.jitter;
            if (!spotRadii.empty()) {
                const auto n = std::size_t(std::count(spotRadii.begin(), spotRadii.end(), ',')) + 1;
                r.input.radii = vdbexport::parseNumberList("--radii", spotRadii, "R1,R2,... (output voxels)", n);
            }
            if (oHaloScale->count()) r.input.haloScale = cli.input.haloScale;
            if (!surfaceScalar.empty()) {
                if (!r.input.surface) r.input.surface = vdbexport::SurfaceSpec{};
                r.input.surface->scalar = surfaceScalar;
            }
            if (oSurfaceThreshold->count()) {
                if (!r.input.surface) throw lic::InputError("--surface-threshold needs --surface SCALAR");
                r.input.surface->threshold = surfaceThreshold;
            }
            if (!roiScalar.empty()) {
                if (!r.roi && roiRange.empty())
                    throw lic::InputError("--roi " + roiScalar + " needs --roi-range LO,HI (the kept range in the scalar's units)");
                if (!r.roi) r.roi = vdbexport::RoiSpec{};
                r.roi->scalar = roiScalar;
            }
            if (!roiRange.empty()) {
                if (!r.roi) throw lic::InputError("--roi-range needs --roi SCALAR");
                const auto v = vdbexport::parseNumberList("--roi-range", roiRange, "LO,HI", 2);
                r.roi->range = {v[0], v[1]};
            }
            if (oRoiMode->count()) {
                if (!r.roi) throw lic::InputError("--roi-mode needs --roi SCALAR");
                r.roi->mode = roiMode;
            }
            if (!widthScalar.empty()) {
                if (!r.width) r.width = vdbexport::WidthSpec{};
                r.width->scalar = widthScalar;
            }
            if (!widthRange.empty()) {
                if (!r.width) throw lic::InputError("--width-range needs --width SCALAR");
                const auto v = vdbexport::parseNumberList("--width-range", widthRange, "LO,HI", 2);
                r.width->range = std::array<double, 2>{v[0], v[1]};
            }
            if (widthInvert) {
                if (!r.width) throw lic::InputError("--width-invert needs --width SCALAR");
                r.width->invert = true;
            }
            if (writeSeries) r.output.writeSeries = true;
            if (bake->get_option("--threads")->count()) r.threads = bakeCommon.threads;
            vdbexport::checkNotOverwritten(r, recipePath, "the recipe");

            // Under mpirun every rank runs this; rank 0 alone reports progress and the summary.
            mpi.start(argc, argv);
            const bool quiet = bakeCommon.quiet || mpi.rank() != 0;
            vdbexport::TerminalProgress progress(quiet, stderr, false, bakeCommon.progressStyle());
            gProgress = &progress;
            const ProgressGuard progressGuard; // declared after `progress`, so destroyed first
            std::signal(SIGINT, onInterrupt);
            const nlohmann::json summary = vdbexport::bake(r, progress);
            progress.finishLine();
            gProgress = nullptr;
            if (mpi.rank() != 0) return 0;
            if (!bakeCommon.quiet && summary.contains("field") && summary["field"].contains("notes"))
                for (const auto& note : summary["field"]["notes"]) std::cerr << "licvdb bake: " << note.get<std::string>() << "\n";
            if (bakeCommon.json) {
                std::cout << summary.dump(2) << "\n";
            } else if (!bakeCommon.quiet) {
                std::fprintf(stderr, "wrote %s (%llu voxels, %.2f s%s)\n", r.output.path.c_str(),
                             (unsigned long long)summary["output_voxels"].get<std::uint64_t>(),
                             summary["seconds"]["total"].get<double>(),
                             mpi.distributed() ? (", " + std::to_string(mpi.size()) + " ranks").c_str() : "");
            }
            return 0;
        }
    } catch (const lic::Cancelled&) {
        if (gProgress) gProgress->finishLine();
        if (mpi.reportsErrors()) std::cerr << currentCommand << ": cancelled; no output written\n";
        return mpi.failed(1);
    } catch (const lic::InputError& e) {
        if (gProgress) gProgress->finishLine();
        if (mpi.reportsErrors()) {
            std::cerr << currentCommand << ": error: " << mpi.errorPrefix() << e.what() << "\n";
            std::cerr << "see `licvdb help " << (currentCommand == "licvdb" ? "" : currentCommand.substr(7)) << "`\n";
        }
        return mpi.failed(2);
    } catch (const std::bad_alloc&) {
        if (gProgress) gProgress->finishLine();
        if (mpi.reportsErrors())
            std::cerr << currentCommand << ": error: " << mpi.errorPrefix() << "out of memory\n";
        return mpi.failed(1);
    } catch (const std::exception& e) {
        if (gProgress) gProgress->finishLine();
        if (mpi.reportsErrors())
            std::cerr << currentCommand << ": error: " << mpi.errorPrefix() << e.what() << "\n";
        return mpi.failed(1);
    }
    return 0;
}

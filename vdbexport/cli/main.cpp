// licvdb: bake 3D line integral convolution of vector fields into OpenVDB volumes.
//
// Subcommands: field, bake, info, help, version. Only main() catches: lic::InputError and usage
// errors exit 2, other failures exit 1. Progress goes to stderr when it is a terminal; --json
// puts a machine-readable summary on stdout.

#include "vdbexport/Bake.h"
#include "vdbexport/Info.h"
#include "vdbexport/Recipe.h"
#include "vdbexport/TerminalProgress.h"
#include "vdbexport/VdbIO.h"

#include "lic/Error.h"
#include "lic/FieldPresets.h"

#include <CLI/CLI.hpp>
#include <openvdb/openvdb.h>

#include <csignal>
#include <cstdio>
#include <iostream>
#include <sstream>

namespace {

vdbexport::TerminalProgress* gProgress = nullptr;

extern "C" void onInterrupt(int)
{
    if (gProgress) gProgress->requestCancel();
}

struct Common
{
    bool quiet = false;
    bool json = false;
    int threads = 0;
};

void addCommon(CLI::App* cmd, Common& c)
{
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

std::string presetList()
{
    std::string out;
    for (const auto& name : lic::presetNames())
        out += "  " + name + std::string(name.size() < 12 ? 12 - name.size() : 1, ' ') +
               lic::presetDescription(name) + "\n";
    return out;
}

} // namespace

int main(int argc, char** argv)
{
    CLI::App app{"licvdb: 3D line integral convolution of vector fields, baked into OpenVDB volumes"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("licvdb ") + LICVDB_VERSION);
    app.footer("Run `licvdb help CMD` for a command's options and examples.");
    std::string currentCommand = "licvdb";

    // field ------------------------------------------------------------------------------------
    Common fieldCommon;
    std::string preset, res, fieldOut;
    CLI::App* field = app.add_subcommand("field", "Write an analytic example vector field");
    field->add_option("preset", preset, "Preset name")->required();
    field->add_option("--res", res, "Resolution X,Y,Z in voxels (default per preset)");
    field->add_option("-o,--out", fieldOut, "Output .vdb")->required();
    addCommon(field, fieldCommon);
    field->footer("Presets:\n" + presetList() +
                  "\nExamples:\n  licvdb field abc --res 64,64,64 --out abc.vdb\n"
                  "  licvdb field tabbed-jet --out jet.vdb      # 101x101x148, with `temperature`\n");

    // bake -------------------------------------------------------------------------------------
    Common bakeCommon;
    std::string recipePath;
    vdbexport::Recipe cli; // values of flags that were given
    CLI::App* bake = app.add_subcommand("bake", "Bake a LIC volume from a vector field");
    bake->add_option("-f,--field", cli.field.path, "Field .vdb with a Vec3 grid");
    bake->add_option("--grid", cli.field.grid, "Vector grid name (default: velocity, vel, v, the only Vec3 grid)");
    bake->add_option("-o,--out", cli.output.path, "Output .vdb (a sidecar OUT.json manifest is written too)");
    bake->add_option("-r,--recipe", recipePath, "JSON recipe; flags override its values");
    auto* oInput = bake->add_option("--input", cli.input.type, "Input texture: noise (spots: later)");
    auto* oFilter = bake->add_option("--noise-filter", cli.input.noiseFilter, "Noise reconstruction: binomial|none [binomial]");
    auto* oEngine = bake->add_option("--engine", cli.lic.engine, "naive|fast [fast]");
    auto* oKernel = bake->add_option("--kernel", cli.lic.kernel, "box|exp (oriented streamlets, bright head downstream) [box]");
    auto* oDecay = bake->add_option("--decay", cli.lic.decay, "exp kernel: weight ratio of consecutive samples, (0,1) [0.9]");
    auto* oLength = bake->add_option("--length", cli.lic.length, "Kernel half-length, output voxels [20]");
    auto* oStep = bake->add_option("--step", cli.lic.step, "Sample spacing along streamlines, output voxels [0.5]");
    auto* oIntegrator = bake->add_option("--integrator", cli.lic.integrator, "rk4|rk45 [rk4]");
    auto* oTolerance = bake->add_option("--tolerance", cli.lic.tolerance, "rk45 local error, output voxels [1e-3]");
    auto* oMinHits = bake->add_option("--min-hits", cli.lic.minHits, "fast: deposits a voxel needs before it stops seeding [2]");
    auto* oUpsample = bake->add_option("--upsample", cli.output.upsample, "Output voxels per field voxel [2]");
    auto* oSeed = bake->add_option("--seed", cli.input.seed, "Noise seed [1]");
    auto* oContrast = bake->add_option("--contrast", cli.output.contrast, "stretch|none [stretch]");
    std::string colorScalar, colormap;
    bake->add_option("--color", colorScalar,
                     "Colour by a scalar: speed, vorticity, streamwise-vorticity, helicity, q-criterion, lambda2, or a float grid of the field file");
    auto* oColormap = bake->add_option("--colormap", colormap,
                                       "heated-object|red-yellow|grey-purple|viridis|magma|inferno|cividis|coolwarm or a value,r,g,b .csv [viridis]");
    auto* oFrames = bake->add_option("--frames", cli.animation.frames, "Frames of a cyclic animation [1]");
    bool writeInput = false, writeTangent = false;
    auto* oWriteInput = bake->add_flag("--write-input", writeInput, "Also write the input texture as grid `input`");
    auto* oWriteTangent = bake->add_flag("--write-tangent", writeTangent, "Also write the unit flow direction as vec3s grid `tangent`");
    addCommon(bake, bakeCommon);
    bake->footer(
        "Lengths are in output voxels (field voxel size / upsample).\n\n"
        "Examples:\n"
        "  licvdb field tabbed-jet --out jet.vdb\n"
        "  licvdb bake --field jet.vdb --out jet_lic.vdb\n"
        "  licvdb bake --field abc.vdb --out abc_lic.vdb --length 40 --step 0.5 --json\n"
        "  licvdb bake --recipe examples/recipes/tabbed-jet.json --threads 2\n"
        "  licvdb bake --field jet.vdb --out jet_vort.vdb --color vorticity --colormap heated-object\n");

    // info -------------------------------------------------------------------------------------
    Common infoCommon;
    std::string infoPath;
    CLI::App* info = app.add_subcommand("info", "List the grids, bounding boxes and metadata of a .vdb");
    info->add_option("file", infoPath, "A .vdb file")->required();
    addCommon(info, infoCommon);
    info->footer("Examples:\n  licvdb info jet_lic.vdb\n  licvdb info jet_lic.vdb --json | python3 -m json.tool\n");

    // help / version ---------------------------------------------------------------------------
    std::string helpTopic;
    CLI::App* help = app.add_subcommand("help", "Show help for a command");
    help->add_option("command", helpTopic, "field, bake, info");
    app.add_subcommand("version", "Print the version");

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
                std::cout << app.help();
                return 0;
            }
            CLI::App* sub = nullptr;
            try {
                sub = app.get_subcommand(helpTopic);
            } catch (const CLI::OptionNotFound&) {
            }
            if (!sub) throw lic::InputError("no command \"" + helpTopic + "\"; expected field, bake or info");
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
            const lic::PresetField f = lic::makePresetField(preset, r);
            openvdb::GridPtrVec grids{f.velocity};
            for (const auto& s : f.scalars) grids.push_back(s);
            vdbexport::writeVdbAtomic(fieldOut, grids);
            if (fieldCommon.json) {
                nlohmann::json j{{"output", fieldOut}, {"preset", preset}, {"resolution", {r[0], r[1], r[2]}},
                                 {"grids", nlohmann::json::array()}};
                for (const auto& g : grids) j["grids"].push_back(g->getName());
                std::cout << j.dump(2) << "\n";
            } else if (!fieldCommon.quiet) {
                std::cerr << "wrote " << preset << " field " << r[0] << "x" << r[1] << "x" << r[2] << " to " << fieldOut
                          << "\n";
            }
            return 0;
        }

        if (info->parsed()) {
            currentCommand = "licvdb info";
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
            if (oSeed->count()) r.input.seed = cli.input.seed;
            if (oContrast->count()) r.output.contrast = cli.output.contrast;
            if (oFrames->count()) r.animation.frames = cli.animation.frames;
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
            if (bake->get_option("--threads")->count()) r.threads = bakeCommon.threads;

            vdbexport::TerminalProgress progress(bakeCommon.quiet);
            gProgress = &progress;
            std::signal(SIGINT, onInterrupt);
            const nlohmann::json summary = vdbexport::bake(r, progress);
            progress.finishLine();
            gProgress = nullptr;
            if (bakeCommon.json) {
                std::cout << summary.dump(2) << "\n";
            } else if (!bakeCommon.quiet) {
                std::fprintf(stderr, "wrote %s (%llu voxels, %.2f s)\n", r.output.path.c_str(),
                             (unsigned long long)summary["output_voxels"].get<std::uint64_t>(),
                             summary["seconds"]["total"].get<double>());
            }
            return 0;
        }
    } catch (const lic::Cancelled&) {
        if (gProgress) gProgress->finishLine();
        std::cerr << currentCommand << ": cancelled; no output written\n";
        return 1;
    } catch (const lic::InputError& e) {
        if (gProgress) gProgress->finishLine();
        std::cerr << currentCommand << ": error: " << e.what() << "\n";
        std::cerr << "see `licvdb help " << (currentCommand == "licvdb" ? "" : currentCommand.substr(7)) << "`\n";
        return 2;
    } catch (const std::exception& e) {
        if (gProgress) gProgress->finishLine();
        std::cerr << currentCommand << ": error: " << e.what() << "\n";
        return 1;
    }
    return 0;
}

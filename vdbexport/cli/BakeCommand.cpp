// `licvdb bake`: a recipe (file and flags) → vdbexport::bake, under mpirun shared over the ranks.
#include "Command.h"
#include "Progress.h"
#include "RecipeFlags.h"

#include "vdbexport/bake/Bake.h"
#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/io/Numbers.h"

#include <lic/composite/OutputGrids.h>
#include <lic/engine/Engine.h>
#include <lic/util/Error.h>

#include <algorithm>
#include <cstdio>
#include <iostream>

namespace vdbexport::cli {

namespace {

using nlohmann::json;

/// A flag's list of numbers as the JSON array its recipe key holds.
RecipeFlags::Convert<std::string> numbers(const char* flag, const char* expected, std::size_t count)
{
    return [=](const std::string& text, const json&) { return json(parseNumberList(flag, text, expected, count)); };
}

class BakeCommand final : public CommandWithCommonOptions
{
public:
    void addOptions(CLI::App& cmd) override;
    int run(Context& context) override;

private:
    void addPathFlags(CLI::App& cmd);
    void addLicFlags();
    void addColorFlags();
    void addFieldFlags();
    void addOutputFlags();
    void addSpotFlags();
    void report(const json& summary, const Recipe& recipe, const MpiSession& mpi) const;

    std::string mRecipePath;
    std::unique_ptr<RecipeFlags> mFlags;
};

void BakeCommand::addOptions(CLI::App& cmd)
{
    mFlags = std::make_unique<RecipeFlags>(cmd);
    addPathFlags(cmd);
    addLicFlags();
    addColorFlags();
    addFieldFlags();
    addOutputFlags();
    addSpotFlags();
    addCommonOptions(cmd, mCommon);
    mFlags->bind(mCommon.threadsOption, "threads", mCommon.threads);
    cmd.footer(
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
        "  licvdb bake --field jet.vdb --out seeded.vdb --input spots --seeds points.txt   # lines through your points (x y z, world units)\n"
        "  licvdb bake --field flow.npy --voxel-size 0.1 --origin -1,-1,0 --out flow_lic.vdb\n"
        "  licvdb bake --field flow.raw --shape 64,64,32 --dtype float64 --out flow_lic.vdb\n"
        "Field formats and preparation: see docs/inputs.md.\n");
}

void BakeCommand::addPathFlags(CLI::App& cmd)
{
    RecipeFlags& f = *mFlags;
    f.text("-f,--field", "field.path", "Field: .vdb (a Vec3 grid, or vel.x/.y/.z), .npy, .vti, .vtk or raw (with --shape)");
    f.text("--grid", "field.grid", "Vector grid name (default: velocity, vel, v, the only Vec3 grid)");
    f.text("-o,--out", "output.path", "Output .vdb (a sidecar manifest OUT.licvdb.json is written too)");
    cmd.add_option("-r,--recipe", mRecipePath, "JSON recipe; flags override its values");
}

void BakeCommand::addLicFlags()
{
    RecipeFlags& f = *mFlags;
    f.option<std::string>("--input", "input.type", "Input texture: noise|spots [noise]");
    f.option<std::string>("--noise-filter", "input.noise_filter", "Noise reconstruction: binomial|none [binomial]");
    f.option<std::string>("--engine", "lic.engine",
                          "auto|" + joined(choices().engines) + ": auto = " + lic::toString(lic::chooseEngine("auto", true)) +
                              " for spots, " + lic::toString(lic::chooseEngine("auto", false)) + " for noise [auto]");
    f.option<std::string>("--kernel", "lic.kernel", joined(choices().kernels) +
                                                         " (exp: oriented streamlets, bright head downstream) [box]");
    f.option<double>("--decay", "lic.decay", "exp kernel: weight ratio of consecutive samples, (0,1) [0.9]");
    f.option<double>("--length", "lic.length", "Kernel half-length, output voxels [20]");
    f.option<double>("--step", "lic.step", "Sample spacing along streamlines, output voxels [0.5]");
    f.option<std::string>("--integrator", "lic.integrator", "rk4|rk45 [rk4]");
    f.option<double>("--tolerance", "lic.tolerance", "rk45 local error, output voxels [1e-3]");
    f.option<int>("--min-hits", "lic.min_hits", "fast: deposits a voxel needs before it stops seeding [2]");
    f.option<int>("--brick", "lic.brick", "Brick edge, output voxels: a multiple of 8 in 8..512, or 0 = automatic [0]");
    f.option<int>("--upsample", "output.upsample", "Output voxels per field voxel [2]");
    f.option<std::uint64_t>("--seed", "input.seed", "Hash seed of the noise and of the spot positions [1]");
    f.option<std::string>("--contrast", "output.contrast", "stretch|none [stretch]");
}

void BakeCommand::addColorFlags()
{
    RecipeFlags& f = *mFlags;
    f.text("--color", "color.scalar",
           "Colour by a scalar: " + joined(choices().scalars, ", ") +
               ", or a float grid of the field file; NAME-abs = |NAME|, NAME-gradient = |grad NAME|");
    f.option<std::string>("--colormap", "color.colormap",
                          joined(choices().colormaps) + " or a value,r,g,b .csv [viridis]");
    f.needsSection("color", "--colormap needs a colour scalar: add --color SCALAR");
}

void BakeCommand::addFieldFlags()
{
    RecipeFlags& f = *mFlags;
    f.option<std::string>("--format", "field.format", "Field format: " + joined(choices().formats) + " [auto: by extension]");
    f.option<double>("--voxel-size", "field.voxel_size", "Dense inputs (npy, raw, vti, vtk): world units per voxel [file's, else 1]; meshes: the lattice's voxel size [for LIC: half the 10th percentile of the cell sizes, within a budget]");
    f.option<double>("--time", "field.time", "A series (.pvd, OpenFOAM case): the time to read [the latest]");
    f.text("--solution", "field.solution", "PLOT3D: the solution (.q) file [the grid's name with .q]");
    f.text("--origin", "field.origin", "Dense inputs: world position X,Y,Z of voxel (0,0,0)'s centre [file's, else 0]",
           numbers("--origin", "X,Y,Z", 3));
    f.text("--shape", "field.shape", "Raw input: X,Y,Z voxels (data is X,Y,Z,3 in C order)",
           numbers("--shape", "X,Y,Z (voxels)", 3));
    f.option<std::string>("--dtype", "field.dtype", "Raw input: float32|float64|f4|f8|<f4|>f4|<f8|>f8 [float32]");
    f.option<double>("--resample", "field.resample", "Resample the field to this voxel size, world units");
    f.text("--crop", "field.crop", "Crop the field to world box X0,Y0,Z0,X1,Y1,Z1", [](const std::string& text, const json&) {
        const auto v = parseNumberList("--crop", text, "X0,Y0,Z0,X1,Y1,Z1 (world units)", 6);
        return json::array({json::array({v[0], v[1], v[2]}), json::array({v[3], v[4], v[5]})});
    });
    f.option<std::string>("--mask", "field.mask", "none|zero: zero deactivates zero-velocity voxels [none]");
    f.option<std::string>("--nan-policy", "field.nan_policy", "refuse|zero: NaN/Inf in the field is an error, or set to 0 [refuse]");
    f.option<int>("--frames", "animation.frames", "Frames of a cyclic animation [1]");
    f.option<std::string>("--field-frames", "field.frames",
                          "FIRST,LAST: bake the unsteady sequence --field pattern_####.vdb (default: every frame on disk)",
                          [](const std::string& text, const json& recipe) {
                              const auto [first, last] = parseFrameRange("--field-frames", text);
                              const std::string path = recipe.at("field").at("path").get<std::string>();
                              if (!isFramePattern(path)) {
                                  throw lic::InputError("--field \"" + path + "\" has no frame number: with --field-frames, put a run "
                                                        "of # (or %04d) where it goes, e.g. cache/data/fluid_data_####.vdb");
                              }
                              return json::array({first, last});
                          });
    f.option<double>("--fps", "field.fps", "Unsteady sequence: frames per second (velocity is world units per second) [24]");
}

void BakeCommand::addOutputFlags()
{
    RecipeFlags& f = *mFlags;
    // --write-input, --write-tangent, --write-velocity, --write-series: the output-grid table's
    // grids asked for by a flag (a flag shared by two grids once).
    std::vector<std::string_view> made;
    for (const lic::OutputGridRow& row : lic::outputGrids()) {
        if (row.flag.empty() || std::find(made.begin(), made.end(), row.flag) != made.end()) continue;
        made.push_back(row.flag);
        f.flag(std::string(row.flag), ("output." + std::string(row.recipeKey)).c_str(), std::string(row.help));
    }
    f.flag("--half", "output.half", "Store grids as 16-bit half floats on disk (about half the file size)");
}

/// Spots, halos, width, region and surface of interest.
void BakeCommand::addSpotFlags()
{
    RecipeFlags& f = *mFlags;
    f.option<std::string>("--distribution", "input.distribution", "Spots: regular|random|jittered|poisson [poisson]");
    f.text("--seeds", "input.seeds",
           "Spots: centres from FILE, world units (.npy (N,3) float32/64, or text lines x y z); replaces --distribution");
    f.option<double>("--spacing", "input.spacing", "Spots: spacing d between spot centres, output voxels [6]");
    f.option<double>("--jitter", "input.jitter", "Jittered spots: offset up to ±jitter·d/2 per axis, [0,1] [0.25]");
    f.text("--radii", "input.radii", "Spots: line radii R1,R2,... increasing, output voxels (one per width level, at most 4) [1]",
           [](const std::string& text, const json&) {
               const auto n = std::size_t(std::count(text.begin(), text.end(), ',')) + 1;
               return json(parseNumberList("--radii", text, "R1,R2,... (output voxels)", n));
           });
    f.option<double>("--halo-scale", "input.halo_scale", "Spots: halo radius / line radius, >= 1 [2]");
    f.text("--surface", "input.surface.scalar", "Spots on the ridge surface of a scalar (e.g. speed-gradient = |grad speed|)");
    f.option<double>("--surface-threshold", "input.surface.threshold", "--surface: ridge points need scalar > this [0]");
    f.needsSection("input.surface", "--surface-threshold needs --surface SCALAR");
    f.text("--roi", "roi.scalar", "Region of interest by a scalar (speed, vorticity, a float grid, NAME-gradient, NAME-abs)",
           [&f](const std::string& scalar, const json& recipe) {
               if (isAbsent(recipe, "roi") && !f.given("--roi-range"))
                   throw lic::InputError("--roi " + scalar + " needs --roi-range LO,HI (the kept range in the scalar's units)");
               return json(scalar);
           });
    f.text("--roi-range", "roi.range", "--roi: kept range LO,HI in the scalar's units", numbers("--roi-range", "LO,HI", 2));
    f.needsSection("roi", "--roi-range needs --roi SCALAR");
    f.option<std::string>("--roi-mode", "roi.mode", "--roi: pre (mask the input; lines leave along the flow) | post (mask the output) [pre]");
    f.needsSection("roi", "--roi-mode needs --roi SCALAR");
    f.text("--width", "width.scalar", "Spots: pick the width level per voxel by a scalar (needs 2+ radii)");
    f.text("--width-range", "width.range", "--width: scalar range LO,HI mapped onto narrowest..widest [auto: 1st-99th percentile]",
           numbers("--width-range", "LO,HI", 2));
    f.needsSection("width", "--width-range needs --width SCALAR");
    f.flag("--width-invert", "width.invert", "--width: high scalar = thin lines (the seed shows slow flow wide)");
    f.needsSection("width", "--width-invert needs --width SCALAR");
}

int BakeCommand::run(Context& context)
{
    const Recipe fromFile = mRecipePath.empty() ? Recipe{} : loadRecipeFile(mRecipePath);
    const Recipe recipe = mFlags->apply(fromFile); // flags override the recipe
    checkNotOverwritten(recipe, mRecipePath, "the recipe");

    // Under mpirun every rank runs this; rank 0 alone reports progress and the summary.
    MpiSession& mpi = context.mpi;
    mpi.start(context.argc, context.argv);
    const json summary = runWithProgress(mCommon.quiet || mpi.rank() != 0, mCommon.progressStyle(),
                                         [&](lic::Progress& progress) { return bake(recipe, progress); });
    if (mpi.rank() == 0) report(summary, recipe, mpi);
    return 0;
}

void BakeCommand::report(const json& summary, const Recipe& recipe, const MpiSession& mpi) const
{
    if (!mCommon.quiet && summary.contains("field") && summary["field"].contains("notes"))
        for (const auto& note : summary["field"]["notes"]) std::cerr << "licvdb bake: " << note.get<std::string>() << "\n";
    const json* seeds = summary.contains("spots") && summary["spots"].is_object() && summary["spots"].contains("seeds")
                            ? &summary["spots"]["seeds"] : nullptr;
    if (!mCommon.quiet && seeds && (*seeds)["dropped"].get<std::uint64_t>() > 0) {
        std::cerr << "licvdb bake: " << (*seeds)["dropped"].get<std::uint64_t>() << " of " << (*seeds)["points"].get<std::uint64_t>()
                  << " seed points of " << recipe.input.seeds
                  << " lie outside the output domain (the field's active voxels) and were dropped\n";
    }
    if (mCommon.json) {
        std::cout << summary.dump(2) << "\n";
    } else if (!mCommon.quiet) {
        const std::string ranks = mpi.distributed() ? ", " + std::to_string(mpi.size()) + " ranks" : "";
        if (summary.contains("output_voxels")) {
            std::fprintf(stderr, "wrote %s (%llu voxels, %.2f s%s)\n", recipe.output.path.c_str(),
                         (unsigned long long)summary["output_voxels"].get<std::uint64_t>(),
                         summary["seconds"]["total"].get<double>(), ranks.c_str());
        } else { // a sequence (an unsteady field): its frames' files and the manifest
            const json& files = summary.at("files");
            std::fprintf(stderr, "wrote %zu frames, %s .. %s, and %s (%.2f s%s)\n", files.size(),
                         files.front().get<std::string>().c_str(), files.back().get<std::string>().c_str(),
                         summary.contains("manifest") && summary["manifest"].is_string() ? summary["manifest"].get<std::string>().c_str() : "no manifest",
                         summary["seconds"]["total"].get<double>(), ranks.c_str());
        }
    }
}

} // namespace

std::unique_ptr<Command> makeBakeCommand() { return std::make_unique<BakeCommand>(); }

} // namespace vdbexport::cli

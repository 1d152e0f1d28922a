#include "vdbexport/Bake.h"

#include "bake/Composite.h"
#include "bake/Input.h"
#include "bake/Plan.h"
#include "bake/Scalars.h"
#include "bake/Write.h"

#include "vdbexport/FieldInput.h"

#include "lic/Colormap.h"
#include "lic/Engine.h"
#include "lic/Error.h"

#include <openvdb/openvdb.h>

#include <sys/resource.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

namespace vdbexport {

namespace fs = std::filesystem;

std::string framePath(const std::string& vdbPath, int frame, int frames)
{
    if (frames <= 1) return vdbPath;
    fs::path p(vdbPath);
    char suffix[16];
    std::snprintf(suffix, sizeof suffix, "_%04d", frame);
    const std::string ext = p.extension() == ".vdb" ? ".vdb" : "";
    const fs::path stem = ext.empty() ? p.filename() : p.stem();
    return (p.parent_path() / (stem.string() + suffix + ".vdb")).string();
}

std::string manifestPath(const std::string& vdbPath)
{
    fs::path p(vdbPath);
    if (p.extension() == ".vdb") p.replace_extension(".json");
    else p += ".json";
    return p.string();
}

void checkNotOverwritten(const Recipe& recipe, const std::string& path, const std::string& what)
{
    if (path.empty()) return;
    std::error_code ec;
    const fs::path input = fs::weakly_canonical(path, ec);
    if (ec) return; // cannot be resolved: reading it will report the problem
    std::vector<std::string> outputs{manifestPath(recipe.output.path)};
    for (int f = 1; f <= recipe.animation.frames; ++f)
        outputs.push_back(framePath(recipe.output.path, f, recipe.animation.frames));
    for (const auto& out : outputs) {
        std::error_code e1, e2;
        const bool same = fs::equivalent(path, out, e1) || fs::weakly_canonical(out, e2) == input;
        if (same && !e2) {
            throw lic::InputError("the bake would overwrite " + what + " \"" + path + "\" with \"" + out +
                                  "\"; choose another --out");
        }
    }
}

namespace {

lic::Colormap loadColormap(const std::string& spec)
{
    if (fs::path(spec).extension() != ".csv") return lic::Colormap::named(spec);
    std::ifstream in(spec);
    if (!in) throw lic::InputError("colormap LUT file \"" + spec + "\" cannot be read");
    std::stringstream text;
    text << in.rdbuf();
    return lic::Colormap::fromCsv(text.str(), spec);
}

/// Peak resident memory of this process so far, MiB (Linux: ru_maxrss is in KiB).
double peakRssMiB()
{
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0;
}

} // namespace

// The pipeline of DESIGN.md, top to bottom; each stage lives in src/bake/.
nlohmann::json bake(const Recipe& request, lic::Progress& progress)
{
    // The engine "auto" is resolved here, so the recipe a bake records names the engine it used.
    Recipe recipe = request;
    if (recipe.lic.engine == "auto") recipe.lic.engine = recipe.input.type == "spots" ? "splat" : "fast";
    using Clock = std::chrono::steady_clock;
    auto seconds = [](Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); };
    const auto t0 = Clock::now();

    // 1. Plan: every setting and every check that needs only the recipe.
    const pipeline::Plan plan = pipeline::makePlan(recipe);
    openvdb::initialize();

    // 2. Field: any format (vdb, npy, vti, vtk, raw), prepared (NaN policy, crop, mask,
    //    resample); the file's scalar grids come with it. The output domain and its bricks.
    const LoadedField loaded = loadField(recipe.field);
    const lic::VelocityField field(loaded.velocity);
    const lic::OutputDomain domain(field, recipe.output.upsample);
    const lic::BrickLayout layout(domain, lic::detail::brickDim(plan.settings));
    const double tRead = seconds(t0);

    // 3. Scalars by name, and the automatic ranges of width and colour (streamed percentiles).
    const auto t1 = Clock::now();
    pipeline::ScalarSet scalars(*loaded.velocity, loaded.scalars);
    pipeline::Ranges ranges;
    if (recipe.width) {
        ranges.width = recipe.width->range ? *recipe.width->range
                                           : pipeline::autoRange(pipeline::ScalarField(scalars.get(recipe.width->scalar)), domain, recipe.threads);
    }
    std::optional<lic::Colormap> cmap;
    if (recipe.color) {
        cmap = loadColormap(recipe.color->colormap);
        ranges.color = recipe.color->range ? *recipe.color->range
                                           : pipeline::autoRange(pipeline::ScalarField(scalars.get(recipe.color->scalar)), domain, recipe.threads);
    }

    // 4. Input texture: spots placed once; noise made per brick.
    pipeline::Input input = pipeline::makeInput(plan, domain, scalars);
    const double tInput = seconds(t1);

    // 5–6. Convolve each brick and composite it into leaves as it finishes.
    pipeline::Compositor compositor(plan, field, domain, layout, scalars, input, cmap ? &*cmap : nullptr, ranges);
    const lic::BrickSink sink = [&](const lic::BrickChannels& b) { compositor.consume(b); };
    const lic::LicStats st =
        plan.spots ? lic::convolveSpotBricks(field, domain, layout, input.spots, recipe.input.radii,
                                             recipe.input.haloScale, plan.settings, progress, sink)
                   : lic::convolveNoiseBricks(field, domain, layout, *input.noise, plan.settings, progress, sink);
    const auto t2 = Clock::now();
    compositor.finish();
    const double tCompose = seconds(t2);

    // 7. Metadata, files, manifest.
    const auto t3 = Clock::now();
    const nlohmann::json resolved = recipe.toJson();
    openvdb::MetaMap densityMeta; // on `density` of every frame
    densityMeta.insertMeta("licvdb_version", openvdb::StringMetadata(LICVDB_VERSION));
    densityMeta.insertMeta("licvdb_recipe", openvdb::StringMetadata(resolved.dump()));
    densityMeta.insertMeta("licvdb_field_grid", openvdb::StringMetadata(loaded.gridName));
    densityMeta.insertMeta("lic_engine", openvdb::StringMetadata(recipe.lic.engine));
    densityMeta.insertMeta("lic_kernel", openvdb::StringMetadata(recipe.lic.kernel));
    densityMeta.insertMeta("lic_length", openvdb::FloatMetadata(float(recipe.lic.length)));
    densityMeta.insertMeta("lic_step", openvdb::FloatMetadata(float(recipe.lic.step)));
    densityMeta.insertMeta("lic_brick", openvdb::Int32Metadata(layout.dim()));
    if (plan.settings.kernel == lic::KernelType::Exp) {
        densityMeta.insertMeta("lic_decay", openvdb::FloatMetadata(float(recipe.lic.decay)));
        densityMeta.insertMeta("lic_orientation", openvdb::StringMetadata("bright head downstream"));
    }
    densityMeta.insertMeta("lic_frames", openvdb::Int32Metadata(plan.frames));
    densityMeta.insertMeta("lic_cyclic", openvdb::BoolMetadata(plan.frames > 1));
    densityMeta.insertMeta("lic_input", openvdb::StringMetadata(recipe.input.type));
    nlohmann::json spotsJson = nullptr;
    if (plan.spots) {
        const std::string placement = recipe.input.surface ? "surface" : recipe.input.distribution;
        densityMeta.insertMeta("lic_spot_count", openvdb::Int64Metadata(openvdb::Int64(input.spots.centers.size())));
        densityMeta.insertMeta("lic_spot_placement", openvdb::StringMetadata(placement));
        densityMeta.insertMeta("lic_halo_scale", openvdb::FloatMetadata(float(recipe.input.haloScale)));
        spotsJson = {{"count", input.spots.centers.size()}, {"placement", placement},
                     {"spacing", recipe.input.spacing}, {"radii", recipe.input.radii},
                     {"halo_scale", recipe.input.haloScale}, {"line_peaks", plan.linePeak}, {"halo_peaks", plan.haloPeak}};
        if (recipe.width) {
            densityMeta.insertMeta("lic_width_scalar", openvdb::StringMetadata(recipe.width->scalar));
            densityMeta.insertMeta("lic_width_range",
                                   openvdb::Vec2DMetadata(openvdb::Vec2d(ranges.width[0], ranges.width[1])));
            spotsJson["width"] = {{"scalar", recipe.width->scalar}, {"range", ranges.width},
                                  {"invert", recipe.width->invert}};
        }
    }
    nlohmann::json colorJson = nullptr;
    if (recipe.color) {
        densityMeta.insertMeta("lic_color_scalar", openvdb::StringMetadata(recipe.color->scalar));
        densityMeta.insertMeta("lic_colormap", openvdb::StringMetadata(cmap->name()));
        densityMeta.insertMeta("lic_color_range", openvdb::Vec2DMetadata(openvdb::Vec2d(ranges.color[0], ranges.color[1])));
        nlohmann::json points = nlohmann::json::array();
        for (const auto& [pos, c] : cmap->points()) points.push_back({pos, c[0], c[1], c[2]});
        colorJson = {{"scalar", recipe.color->scalar}, {"name", cmap->name()}, {"range", {ranges.color[0], ranges.color[1]}},
                     {"space", "sRGB"}, {"points", points}};
    }
    const pipeline::Written written = pipeline::writeFrames(plan, compositor, densityMeta, progress);
    pipeline::writeManifest(plan, written, domain.voxelSize(), resolved, colorJson, spotsJson);
    const double tWrite = seconds(t3);

    const lic::ChannelStats& raw = compositor.rawStats();
    return {
        {"output", recipe.output.path},
        {"files", written.paths},
        {"frames", plan.frames},
        {"manifest", manifestPath(recipe.output.path)},
        {"field", {{"path", recipe.field.path}, {"grid", loaded.gridName}, {"format", loaded.format}, {"notes", loaded.notes},
                   {"active_voxels", field.activeVoxelCount()}, {"world_bbox", pipeline::bboxJson(field.worldBBox())}}},
        {"engine", recipe.lic.engine},
        {"output_voxels", st.voxels},
        {"output_bbox", {{domain.indexBBox().min()[0], domain.indexBBox().min()[1], domain.indexBBox().min()[2]},
                         {domain.indexBBox().max()[0], domain.indexBBox().max()[1], domain.indexBBox().max()[2]}}},
        {"streamlines", st.streamlines},
        {"samples", st.samples},
        {"samples_per_voxel", st.samplesPerVoxel()},
        {"deposits", st.deposits},
        {"bricks", st.bricks},
        {"brick_size", st.brickDim},
        {"spots", spotsJson},
        {"density_active_voxels", written.firstGrids.front()->activeVoxelCount()},
        {"raw_mean", raw.mean},
        {"raw_stddev", raw.stddev},
        {"peak_rss_mib", peakRssMiB()},
        {"seconds", {{"read", tRead}, {"input", tInput}, {"convolve", st.seconds}, {"compose", tCompose},
                     {"write", tWrite}, {"total", seconds(t0)}}},
    };
}

} // namespace vdbexport

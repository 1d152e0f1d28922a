#include "Write.h"

#include "vdbexport/io/Sha256.h"

#include "vdbexport/io/OutputNames.h"
#include "vdbexport/io/OutputSet.h"

#include "lic/composite/Colormap.h"

#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <filesystem>
#include <optional>

namespace vdbexport::pipeline {

namespace fs = std::filesystem;

nlohmann::json bboxJson(const openvdb::BBoxd& b)
{
    return {{b.min()[0], b.min()[1], b.min()[2]}, {b.max()[0], b.max()[1], b.max()[2]}};
}

openvdb::BBoxd worldBBoxOf(const openvdb::GridBase& grid)
{
    const openvdb::CoordBBox ib = grid.evalActiveVoxelBoundingBox();
    return grid.transform().indexToWorld(
        openvdb::BBoxd(ib.min().asVec3d() - openvdb::Vec3d(0.5), ib.max().asVec3d() + openvdb::Vec3d(0.5)));
}

Description describeBake(const Plan& plan, const nlohmann::json& resolved, const std::string& fieldGrid, int brickDim,
                         std::uint64_t spotCount, const Ranges& ranges, const lic::Colormap* cmap)
{
    const Recipe& recipe = plan.recipe;
    Description d;
    d.densityMeta.insertMeta("licvdb_version", openvdb::StringMetadata(LICVDB_VERSION));
    d.densityMeta.insertMeta("licvdb_recipe", openvdb::StringMetadata(resolved.dump()));
    d.densityMeta.insertMeta("licvdb_field_grid", openvdb::StringMetadata(fieldGrid));
    d.densityMeta.insertMeta("lic_engine", openvdb::StringMetadata(recipe.lic.engine));
    d.densityMeta.insertMeta("lic_kernel", openvdb::StringMetadata(recipe.lic.kernel));
    d.densityMeta.insertMeta("lic_length", openvdb::FloatMetadata(float(recipe.lic.length)));
    d.densityMeta.insertMeta("lic_step", openvdb::FloatMetadata(float(recipe.lic.step)));
    d.densityMeta.insertMeta("lic_brick", openvdb::Int32Metadata(brickDim));
    if (plan.settings.kernel == lic::KernelType::Exp) {
        d.densityMeta.insertMeta("lic_decay", openvdb::FloatMetadata(float(recipe.lic.decay)));
        d.densityMeta.insertMeta("lic_orientation", openvdb::StringMetadata("bright head downstream"));
    }
    d.densityMeta.insertMeta("lic_input", openvdb::StringMetadata(recipe.input.type));
    if (plan.spots) {
        const std::string placement = recipe.input.surface      ? "surface"
                                      : !recipe.input.seeds.empty() ? "seeds"
                                                                    : recipe.input.distribution;
        d.densityMeta.insertMeta("lic_spot_count", openvdb::Int64Metadata(openvdb::Int64(spotCount)));
        d.densityMeta.insertMeta("lic_spot_placement", openvdb::StringMetadata(placement));
        d.densityMeta.insertMeta("lic_halo_scale", openvdb::FloatMetadata(float(recipe.input.haloScale)));
        d.spots = {{"count", spotCount}, {"placement", placement},
                   {"spacing", recipe.input.spacing}, {"radii", recipe.input.radii},
                   {"halo_scale", recipe.input.haloScale}, {"line_peaks", plan.linePeak}, {"halo_peaks", plan.haloPeak}};
        if (recipe.width) {
            d.densityMeta.insertMeta("lic_width_scalar", openvdb::StringMetadata(recipe.width->scalar));
            d.densityMeta.insertMeta("lic_width_range",
                                     openvdb::Vec2DMetadata(openvdb::Vec2d(ranges.width[0], ranges.width[1])));
            d.spots["width"] = {{"scalar", recipe.width->scalar}, {"range", ranges.width},
                                {"invert", recipe.width->invert}};
        }
    }
    if (recipe.color) {
        d.densityMeta.insertMeta("lic_color_scalar", openvdb::StringMetadata(recipe.color->scalar));
        d.densityMeta.insertMeta("lic_colormap", openvdb::StringMetadata(cmap->name()));
        d.densityMeta.insertMeta("lic_color_range", openvdb::Vec2DMetadata(openvdb::Vec2d(ranges.color[0], ranges.color[1])));
        nlohmann::json points = nlohmann::json::array();
        for (const auto& [pos, c] : cmap->points()) points.push_back({pos, c[0], c[1], c[2]});
        d.color = {{"scalar", recipe.color->scalar}, {"name", cmap->name()}, {"range", {ranges.color[0], ranges.color[1]}},
                   {"space", "sRGB"}, {"points", points}};
    }
    return d;
}

void describeSeeds(Description& d, const Recipe& recipe, const Input& input)
{
    if (recipe.input.seeds.empty()) return;
    const std::string sha = sha256OfFile(recipe.input.seeds);
    d.densityMeta.insertMeta("lic_seeds_sha256", openvdb::StringMetadata(sha));
    d.densityMeta.insertMeta("lic_seeds_dropped", openvdb::Int64Metadata(openvdb::Int64(input.seedsDropped)));
    if (d.spots.is_object())
        d.spots["seeds"] = {{"path", recipe.input.seeds}, {"sha256", sha}, {"points", input.seedsRead},
                            {"dropped", input.seedsDropped}};
}

namespace {

/// A frame's metadata (`densityMeta` and `lic_frame` on `density`) and half floats if asked. The
/// grids every frame shares (tangent, colour...) are flagged once, by frame 1: later frames only
/// read them, so they may be written while the next frame is prepared.
void prepareFrame(const Recipe& recipe, openvdb::GridPtrVec& grids, const openvdb::MetaMap& densityMeta, int frameNumber)
{
    openvdb::GridBase& density = *grids.front();
    for (auto it = densityMeta.beginMeta(); it != densityMeta.endMeta(); ++it) density.insertMeta(it->first, *it->second);
    density.insertMeta("lic_frame", openvdb::Int32Metadata(frameNumber));
    if (recipe.output.half)
        for (const auto& g : grids)
            if (!g->saveFloatAsHalf()) g->setSaveFloatAsHalf(true);
}

/// The frames of one process (nothing to gather): composed in order, written (compressed,
/// checked, hashed) on up to one thread per core at once, added to the set in order. At most that
/// many frames' grids are held at a time. The files are the same bytes as written one by one.
void writeFramesConcurrently(const Recipe& r, lic::Compositor& compositor, const openvdb::MetaMap& densityMeta,
                             lic::Progress& progress, int frames, Written& out,
                             const vdbexport::detail::SealedLeaves* sealed)
{
    struct Job
    {
        int frame = 0;
        openvdb::GridPtrVec grids;
        std::optional<OutputSet::Pending> file;
    };
    using JobPtr = std::shared_ptr<Job>;
    int next = 1;
    bool cancelled = false;
    const auto tokens = std::size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, JobPtr>(tbb::filter_mode::serial_in_order,
                                       [&](tbb::flow_control& fc) -> JobPtr {
                                           if (next > frames || progress.wasInterrupted()) {
                                               cancelled = next <= frames;
                                               fc.stop();
                                               return nullptr;
                                           }
                                           auto job = std::make_shared<Job>();
                                           job->frame = next++;
                                           job->grids = compositor.frame(job->frame);
                                           prepareFrame(r, job->grids, densityMeta, job->frame);
                                           return job;
                                       })
            & tbb::make_filter<JobPtr, JobPtr>(tbb::filter_mode::parallel,
                                               [&](JobPtr job) {
                                                   job->file.emplace(OutputSet::writeVdb(
                                                       out.paths[std::size_t(job->frame - 1)], job->grids, {}, sealed));
                                                   return job;
                                               })
            & tbb::make_filter<JobPtr, void>(tbb::filter_mode::serial_in_order, [&](JobPtr job) {
                  out.output->add(std::move(*job->file));
                  if (job->frame == 1) out.firstGrids = job->grids;
                  progress.advance(1);
              }));
    if (cancelled) throw lic::Cancelled();
}

} // namespace

void stageFrame(const Recipe& recipe, openvdb::GridPtrVec& grids, const openvdb::MetaMap& densityMeta, int frameNumber,
                const std::string& path, OutputSet& output, const vdbexport::detail::SealedLeaves* sealed)
{
    prepareFrame(recipe, grids, densityMeta, frameNumber);
    output.addVdb(path, grids, {}, sealed);
}

nlohmann::json gridsJson(const openvdb::GridPtrVec& grids)
{
    nlohmann::json out = nlohmann::json::array();
    for (const auto& g : grids) {
        const openvdb::Vec3d vs = g->voxelSize();
        out.push_back({{"name", g->getName()},
                       {"type", g->valueType()},
                       {"active_voxels", g->activeVoxelCount()},
                       {"voxel_size", {vs[0], vs[1], vs[2]}},
                       {"world_bbox", bboxJson(worldBBoxOf(*g))}});
    }
    return out;
}

Written writeFrames(const Plan& plan, lic::Compositor& compositor, const openvdb::MetaMap& densityMeta,
                    lic::Progress& progress, const FrameHook& gather, const vdbexport::detail::SealedLeaves* sealed)
{
    const Recipe& r = plan.recipe;
    Written out;
    for (int f = 1; f <= plan.frames; ++f) out.paths.push_back(framePath(r.output.path, f, plan.frames));
    progress.begin(plan.frames > 1 ? "writing frames" : "writing", std::uint64_t(plan.frames));
    out.output = std::make_shared<OutputSet>(); // staged unseen; nothing to remove on failure
    if (!gather && plan.frames > 1) {
        writeFramesConcurrently(r, compositor, densityMeta, progress, plan.frames, out, sealed);
    } else {
        for (int f = 1; f <= plan.frames; ++f) {
            if (progress.wasInterrupted()) throw lic::Cancelled();
            openvdb::GridPtrVec grids = compositor.frame(f);
            if (gather) gather(f, grids);
            stageFrame(r, grids, densityMeta, f, out.paths[std::size_t(f - 1)], *out.output, sealed);
            if (f == 1) out.firstGrids = grids;
            progress.advance(1);
        }
    }
    progress.end();
    return out;
}

void writeManifest(const Recipe& recipe, const nlohmann::json& resolved, const std::vector<std::string>& paths,
                   OutputSet& output, const nlohmann::json& grids, double voxelSize, const nlohmann::json& colorJson,
                   const nlohmann::json& spotsJson, const nlohmann::json& extra)
{
    nlohmann::json manifest;
    manifest["licvdb_version"] = LICVDB_VERSION;
    manifest["recipe"] = resolved;
    manifest["frames"] = paths.size();
    manifest["cyclic"] = paths.size() > 1;
    manifest["files"] = nlohmann::json::array();
    for (const auto& p : paths) manifest["files"].push_back(fs::path(p).filename().string());
    manifest["voxel_size"] = voxelSize;
    manifest["colormap"] = colorJson;
    manifest["input"] = recipe.input.type;
    manifest["spots"] = spotsJson;
    manifest["range"] = colorJson.is_null() ? nlohmann::json(nullptr) : colorJson["range"];
    manifest["grids"] = grids;
    for (const auto& p : paths) manifest["sha256"][fs::path(p).filename().string()] = output.sha256(p);
    manifest.update(extra);
    output.addText(manifestPath(recipe.output.path), manifest.dump(2) + "\n");
    output.commit(); // frames first, manifest last, under a lock on the directory
}

} // namespace vdbexport::pipeline

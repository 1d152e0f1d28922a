#include "Write.h"

#include "vdbexport/Bake.h"
#include "vdbexport/VdbIO.h"

#include <filesystem>

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

Written writeFrames(const Plan& plan, Compositor& compositor, const openvdb::MetaMap& densityMeta,
                    lic::Progress& progress, const FrameHook& gather)
{
    const Recipe& r = plan.recipe;
    Written out;
    for (int f = 1; f <= plan.frames; ++f) out.paths.push_back(framePath(r.output.path, f, plan.frames));
    progress.begin(plan.frames > 1 ? "writing frames" : "writing", std::uint64_t(plan.frames));
    out.output = std::make_shared<OutputSet>(); // staged unseen; nothing to remove on failure
    {
        for (int f = 1; f <= plan.frames; ++f) {
            if (progress.wasInterrupted()) throw lic::Cancelled();
            openvdb::GridPtrVec grids = compositor.frame(f);
            if (gather) gather(f, grids);
            openvdb::GridBase& density = *grids.front();
            for (auto it = densityMeta.beginMeta(); it != densityMeta.endMeta(); ++it) density.insertMeta(it->first, *it->second);
            density.insertMeta("lic_frame", openvdb::Int32Metadata(f));
            if (r.output.half)
                for (const auto& g : grids) g->setSaveFloatAsHalf(true);
            out.output->addVdb(out.paths[std::size_t(f - 1)], grids);
            if (f == 1) out.firstGrids = grids;
            progress.advance(1);
        }
    }
    progress.end();
    return out;
}

void writeManifest(const Plan& plan, const Written& written, double voxelSize, const nlohmann::json& resolved,
                   const nlohmann::json& colorJson, const nlohmann::json& spotsJson)
{
    nlohmann::json manifest;
    manifest["licvdb_version"] = LICVDB_VERSION;
    manifest["recipe"] = resolved;
    manifest["frames"] = plan.frames;
    manifest["cyclic"] = plan.frames > 1;
    manifest["files"] = nlohmann::json::array();
    for (const auto& p : written.paths) manifest["files"].push_back(fs::path(p).filename().string());
    manifest["voxel_size"] = voxelSize;
    manifest["colormap"] = colorJson;
    manifest["input"] = plan.recipe.input.type;
    manifest["spots"] = spotsJson;
    manifest["range"] = colorJson.is_null() ? nlohmann::json(nullptr) : colorJson["range"];
    manifest["grids"] = nlohmann::json::array();
    for (const auto& g : written.firstGrids) {
        const openvdb::Vec3d vs = g->voxelSize();
        manifest["grids"].push_back({{"name", g->getName()},
                                     {"type", g->valueType()},
                                     {"active_voxels", g->activeVoxelCount()},
                                     {"voxel_size", {vs[0], vs[1], vs[2]}},
                                     {"world_bbox", bboxJson(worldBBoxOf(*g))}});
    }
    for (const auto& p : written.paths) manifest["sha256"][fs::path(p).filename().string()] = written.output->sha256(p);
    written.output->addText(manifestPath(plan.recipe.output.path), manifest.dump(2) + "\n");
    written.output->commit(); // frames first, manifest last, under a lock on the directory
}

} // namespace vdbexport::pipeline

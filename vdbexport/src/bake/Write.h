// Stage 7 of a bake: write. The frames (one file, or OUT_0001 … OUT_NNNN for a loop) each written
// atomically as soon as its grids are composed, then the manifest; a failure removes every frame
// already written, so a failed bake leaves nothing.
#pragma once

#include "Composite.h"
#include "Plan.h"

#include "lic/Progress.h"

#include <nlohmann/json.hpp>

#include <openvdb/openvdb.h>

#include <functional>
#include <string>
#include <vector>

namespace vdbexport::pipeline {

struct Written
{
    std::vector<std::string> paths;     ///< the frame files, in order
    openvdb::GridPtrVec firstGrids;     ///< frame 1's grids as written (for the manifest and summary)
};

/// Called with each frame's grids as composed here, before they are written: a distributed
/// bake adds the other processes' leaves.
using FrameHook = std::function<void(int frame, openvdb::GridPtrVec& grids)>;

/// Write every frame: `densityMeta` goes on each frame's `density` grid, with `lic_frame`.
Written writeFrames(const Plan& plan, Compositor& compositor, const openvdb::MetaMap& densityMeta,
                    lic::Progress& progress, const FrameHook& gather = {});

/// Write the sidecar manifest of a bake (atomically), after its frames.
void writeManifest(const Plan& plan, const Written& written, double voxelSize, const nlohmann::json& resolved,
                   const nlohmann::json& colorJson, const nlohmann::json& spotsJson);

/// World bounds of a grid's active voxels' extents (index bbox ± ½ voxel through the transform).
openvdb::BBoxd worldBBoxOf(const openvdb::GridBase& grid);
nlohmann::json bboxJson(const openvdb::BBoxd& b);

} // namespace vdbexport::pipeline

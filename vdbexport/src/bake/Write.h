// Stage 7 of a bake: write. The frames (one file, or OUT_0001 … OUT_NNNN for a loop) are each
// staged out of sight as soon as its grids are composed, then the manifest with their SHA-256;
// then all are committed together (vdbexport::OutputSet): a failed or killed bake leaves nothing,
// and two bakes to one output never leave the manifest of one beside the frames of the other.
#pragma once

#include "bake/Frame.h"
#include "bake/Plan.h"

#include "lic/composite/Compositor.h"

#include "lic/util/Progress.h"
#include "vdbexport/io/OutputSet.h"

#include <nlohmann/json.hpp>

#include <openvdb/openvdb.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace vdbexport::pipeline {

struct Written
{
    std::vector<std::string> paths;     ///< the frame files, in order
    openvdb::GridPtrVec firstGrids;     ///< frame 1's grids as written (for the manifest and summary)
    std::shared_ptr<OutputSet> output;  ///< the staged frames, committed by writeManifest
};

/// Called with each frame's grids as composed here, before they are written: a distributed
/// bake adds the other processes' leaves.
using FrameHook = std::function<void(int frame, openvdb::GridPtrVec& grids)>;

/// What a bake's files say about it: the metadata on every frame's `density` grid (version,
/// recipe, engine, kernel, spots, colour; not the frame counters) and the manifest's `spots` and
/// `colormap` sections (null when unused).
struct Description
{
    openvdb::MetaMap densityMeta;
    nlohmann::json spots = nullptr, color = nullptr;
};
Description describeBake(const Plan& plan, const nlohmann::json& resolved, const std::string& fieldGrid, int brickDim,
                         std::uint64_t spotCount, const Ranges& ranges, const lic::Colormap* cmap);

/// With input.seeds: the seeds file's path, SHA-256, point count and how many were dropped (off the
/// output domain), as `density` metadata (`lic_seeds_sha256`, `lic_seeds_dropped`) and the
/// manifest's `spots.seeds`.
void describeSeeds(Description& d, const Recipe& recipe, const Input& input);

/// Stage one frame's grids for `path`: `densityMeta` and `lic_frame` = frameNumber on `density`,
/// half floats if the recipe asks. `sealed`: the records of grids whose leaves were sealed.
void stageFrame(const Recipe& recipe, openvdb::GridPtrVec& grids, const openvdb::MetaMap& densityMeta, int frameNumber,
                const std::string& path, OutputSet& output, const vdbexport::detail::SealedLeaves* sealed = nullptr);

/// The manifest's `grids` section: name, type, active voxels, voxel size and world bounds of each.
nlohmann::json gridsJson(const openvdb::GridPtrVec& grids);

/// Write every frame: `densityMeta` goes on each frame's `density` grid, with `lic_frame`.
/// `sealed`: the records of a still's sealed leaves (Compositor::sealLeaves).
Written writeFrames(const Plan& plan, lic::Compositor& compositor, const openvdb::MetaMap& densityMeta,
                    lic::Progress& progress, const FrameHook& gather = {},
                    const vdbexport::detail::SealedLeaves* sealed = nullptr);

/// Write the sidecar manifest of a bake (`paths`: its frame files, staged in `output`, with their
/// SHA-256; `grids`: gridsJson() of the first frame; `extra`: keys added or replaced, e.g. an
/// unsteady sequence's), then commit the frames and the manifest together.
void writeManifest(const Recipe& recipe, const nlohmann::json& resolved, const std::vector<std::string>& paths,
                   OutputSet& output, const nlohmann::json& grids, double voxelSize, const nlohmann::json& colorJson,
                   const nlohmann::json& spotsJson, const nlohmann::json& extra = nlohmann::json::object());

/// World bounds of a grid's active voxels' extents (index bbox ± ½ voxel through the transform).
openvdb::BBoxd worldBBoxOf(const openvdb::GridBase& grid);
nlohmann::json bboxJson(const openvdb::BBoxd& b);

} // namespace vdbexport::pipeline

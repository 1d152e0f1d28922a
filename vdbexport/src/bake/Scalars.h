// Stage 3 of a bake: scalars. Derived scalars and the field file's float grids by name, sampled at
// output voxel centres, and their automatic ranges, all without arrays over the output volume.
#pragma once

#include "lic/OutputDomain.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace vdbexport::pipeline {

/// Scalars of a bake by name: derived (speed, vorticity, …), a float grid of the field file, or
/// NAME-gradient = |∇NAME|. Each is computed once (thread-safe).
class ScalarSet
{
public:
    ScalarSet(const openvdb::Vec3SGrid& velocity, const std::map<std::string, openvdb::FloatGrid::Ptr>& fileScalars)
        : mVelocity(velocity), mFile(fileScalars)
    {
    }
    /// @throw lic::InputError for an unknown name (the message lists the valid ones).
    openvdb::FloatGrid::ConstPtr get(const std::string& name);

private:
    const openvdb::Vec3SGrid& mVelocity;
    const std::map<std::string, openvdb::FloatGrid::Ptr>& mFile;
    std::map<std::string, openvdb::FloatGrid::ConstPtr> mCache;
    std::mutex mMutex;
};

/// The active bounding box of a scalar grid (index space): the box stored on it by
/// setWholeActiveBox() when the grid holds only part of a field (a distributed bake's share),
/// else the grid's own. Probes clamp positions to it, so a part samples like the whole.
openvdb::CoordBBox activeBoxOf(const openvdb::GridBase& grid);
/// Record on `grid` the active bounding box of the whole grid it is a part of.
void setWholeActiveBox(openvdb::GridBase& grid, const openvdb::CoordBBox& box);

/// Trilinear values of a float grid at world positions, the position clamped to the grid's active
/// bounding box (as the velocity sampler does: the outer half voxel repeats the edge value). Holds
/// a value accessor: one probe per thread.
class ScalarProbe
{
public:
    /// `activeBox` = activeBoxOf(grid), computed once by the caller (it walks the tree) when
    /// many probes are made.
    ScalarProbe(const openvdb::FloatGrid& grid, const openvdb::CoordBBox& activeBox);
    explicit ScalarProbe(const openvdb::FloatGrid& grid) : ScalarProbe(grid, activeBoxOf(grid)) {}
    float at(const openvdb::Vec3d& world);

private:
    const openvdb::FloatGrid& mGrid;
    openvdb::FloatGrid::ConstAccessor mAcc;
    openvdb::Vec3d mLo, mHi;
};

/// A scalar grid with its active bounding box, from which per-thread probes are made cheaply.
struct ScalarSource
{
    openvdb::FloatGrid::ConstPtr grid;
    openvdb::CoordBBox box;
    ScalarSource() = default;
    explicit ScalarSource(openvdb::FloatGrid::ConstPtr g) : grid(std::move(g)), box(activeBoxOf(*grid)) {}
    explicit operator bool() const { return bool(grid); }
    ScalarProbe probe() const { return ScalarProbe(*grid, box); }
};

/// Robust automatic range of a scalar: its 1st and 99th percentiles over the active output voxel
/// centres (non-finite values skipped; a constant scalar gives [v, v + 1]). Exact order
/// statistics from two passes of a 65 536-bin histogram over the values' order-preserving bits,
/// so memory does not grow with the volume; deterministic for any thread count.
std::array<double, 2> autoRange(const openvdb::FloatGrid& scalar, const lic::OutputDomain& domain, int threads);

/// Sums histograms over the processes of a distributed bake, in place (Job::sumAll).
using HistogramReduce = std::function<void(std::vector<std::uint64_t>&)>;
/// autoRange() over the voxels of `blocks` only (a process's bricks; null = every block), with
/// each histogram summed by `reduce` over the processes before the percentiles are read from
/// it: integer counts, so the range is exactly that of one process over every block.
std::array<double, 2> autoRange(const openvdb::FloatGrid& scalar, const lic::OutputDomain& domain, int threads,
                                const std::vector<std::uint32_t>* blocks, const HistogramReduce& reduce);

} // namespace vdbexport::pipeline

// Scalars as a bake uses them: derived scalars and the field file's float grids by name
// (ScalarSet), sampled at world positions (ScalarField), and their automatic ranges over the
// output voxels (autoRange), all without arrays over the output volume.
#pragma once

#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace lic {

/// Scalars of a bake by name: derived (speed, vorticity, …), a float grid of the field file,
/// NAME-gradient = |∇NAME|, or NAME-abs = |NAME| (e.g. streamwise-vorticity-abs: the magnitude of
/// a signed scalar). Suffixes nest (speed-gradient-abs). Each is computed once (thread-safe).
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
    openvdb::FloatGrid::ConstPtr resolve(const std::string& name); // get() without the lock

    const openvdb::Vec3SGrid& mVelocity;
    const std::map<std::string, openvdb::FloatGrid::Ptr>& mFile;
    std::map<std::string, openvdb::FloatGrid::ConstPtr> mCache;
    std::mutex mMutex;
};

/// The active bounding box of a scalar grid (index space): the box stored on it by
/// setPartOf() when the grid holds only part of a field (a distributed bake's share), else the
/// grid's own. Samples clamp positions to it, so a part samples like the whole.
openvdb::CoordBBox activeBoxOf(const openvdb::GridBase& grid);
/// The index box a part grid holds values for (setPartOf), else activeBoxOf(grid).
openvdb::CoordBBox partBoxOf(const openvdb::GridBase& grid);
/// Whether setPartOf() marked `grid` as a part.
bool isPart(const openvdb::GridBase& grid);
/// Record on `grid` that it holds the values over `part` (index space) of a whole grid whose
/// active bounding box is `whole`.
void setPartOf(openvdb::GridBase& grid, const openvdb::CoordBBox& whole, const openvdb::CoordBBox& part);

/// A scalar grid prepared for sampling at many world positions: trilinear values, the position
/// clamped to the grid's active bounding box (as the velocity sampler does: the outer half voxel
/// repeats the edge value), from a dense copy of that box (like lic::VelocityField; ~5× faster
/// than a value accessor and BoxSampler). Read-only after construction: share it between threads.
/// For a part of a grid (a distributed bake, setPartOf) positions clamp to the whole grid's box
/// and the dense copy holds only the part: the same arithmetic, so the same bits, wherever the
/// part has values (a rank samples only inside its part; outside, the nearest part voxel).
class ScalarField
{
    /// One axis of a lattice lookup: the two neighbours' offsets into the dense copy and the
    /// weight of the second.
    struct Axis
    {
        std::size_t o0 = 0, o1 = 0;
        double f = 0;
    };
    Axis axis(int a, double idx) const
    {
        const double x = std::clamp(idx, mLo[a], mHi[a]) - mLo[a];
        const int xi = detail::floorIndex(x); // std::floor's integer, without the baseline's long inline floor
        const double fl = double(xi);
        const int i = std::clamp(xi - mOff[a], 0, mDim[a] - 1); // mOff = 0 for a whole grid
        return {std::size_t(i) * mStride[a], std::size_t(std::min(i + 1, mDim[a] - 1)) * mStride[a], x - fl};
    }

public:
    ScalarField() = default;
    /// @throw lic::InputError for a grid with no active voxels, or an active box (of a part: the
    ///        part of it held) of more than 2^28 voxels (crop or resample the field).
    explicit ScalarField(openvdb::FloatGrid::ConstPtr grid);
    explicit operator bool() const { return bool(mGrid); }
    const openvdb::FloatGrid& grid() const { return *mGrid; }

    float at(const openvdb::Vec3d& world) const
    {
        const openvdb::Vec3d idx = AffineMap::apply(mWorldToIndex, world);
        return lerp3(mData.data(), axis(0, idx[0]), axis(1, idx[1]), axis(2, idx[2]));
    }

    /// at() at the voxel centres of one output block at a time (domain.worldOf of each voxel),
    /// the same bits, cheaper. When the output domain's and the scalar's transforms are both
    /// axis-aligned with positive scales (the usual case), a voxel centre's scalar index on each
    /// axis depends on that axis's coordinate only: the zero off-diagonal terms add exact zeros,
    /// so per-axis tables of the lattice offsets and weights give at()'s arithmetic without the
    /// two matrix products and the clamps per voxel. Otherwise it calls at(). One per thread.
    class BlockSampler
    {
    public:
        BlockSampler(const ScalarField& scalar, const OutputDomain& domain);
        /// Prepare the block whose first voxel is `origin`.
        void setBlock(const openvdb::Coord& origin);
        /// The scalar at the centre of the block's voxel `off` (x · 64 + y · 8 + z).
        [[gnu::always_inline]] float at(openvdb::Index off) const
        {
            if (!mSeparable) [[unlikely]]
                return general(off);
            return lerp3(mScalar.mData.data(), mAxis[0][off >> 6], mAxis[1][(off >> 3) & 7u], mAxis[2][off & 7u]);
        }
        /// Whether the per-axis tables are in use (else every voxel calls ScalarField::at).
        bool separable() const { return mSeparable; }

    private:
        float general(openvdb::Index off) const; ///< ScalarField::at at the voxel's centre
        const ScalarField& mScalar;
        const OutputDomain& mDomain;
        openvdb::Coord mOrigin;
        bool mSeparable = false;
        Axis mAxis[3][OutputDomain::kBlockDim];
    };

private:
    [[gnu::always_inline]] static float lerp3(const float* d, const Axis& X, const Axis& Y, const Axis& Z)
    {
        auto lerp = [](double u, double v, double t) { return u + (v - u) * t; };
        const double c00 = lerp(d[X.o0 + Y.o0 + Z.o0], d[X.o0 + Y.o0 + Z.o1], Z.f);
        const double c01 = lerp(d[X.o0 + Y.o1 + Z.o0], d[X.o0 + Y.o1 + Z.o1], Z.f);
        const double c10 = lerp(d[X.o1 + Y.o0 + Z.o0], d[X.o1 + Y.o0 + Z.o1], Z.f);
        const double c11 = lerp(d[X.o1 + Y.o1 + Z.o0], d[X.o1 + Y.o1 + Z.o1], Z.f);
        return float(lerp(lerp(c00, c01, Y.f), lerp(c10, c11, Y.f), X.f));
    }

    openvdb::FloatGrid::ConstPtr mGrid;
    openvdb::Mat4d mWorldToIndex;
    double mLo[3] = {}, mHi[3] = {}; ///< the (whole) active box, clamped to
    int mOff[3] = {};                ///< first voxel of the dense copy, from mLo
    int mDim[3] = {};                ///< voxels of the dense copy
    std::size_t mStride[3] = {};
    std::vector<float> mData;
};

/// Robust automatic range of a scalar: its 1st and 99th percentiles over the active output voxel
/// centres (non-finite values skipped; a constant scalar gives [v, v + 1]). Exact order
/// statistics from two passes of a 65 536-bin histogram over the values' order-preserving bits,
/// so memory does not grow with the volume; deterministic for any thread count.
std::array<double, 2> autoRange(const ScalarField& scalar, const OutputDomain& domain, int threads);

/// Sums histograms over the processes of a distributed bake, in place (an MPI all-reduce).
using HistogramReduce = std::function<void(std::vector<std::uint64_t>&)>;
/// autoRange() over the voxels of `blocks` only (a process's bricks; null = every block), with
/// each histogram summed by `reduce` over the processes before the percentiles are read from
/// it: integer counts, so the range is exactly that of one process over every block.
std::array<double, 2> autoRange(const ScalarField& scalar, const OutputDomain& domain, int threads,
                                const std::vector<std::uint32_t>* blocks, const HistogramReduce& reduce);

} // namespace lic

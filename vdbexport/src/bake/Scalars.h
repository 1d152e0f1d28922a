// Stage 3 of a bake: scalars. Derived scalars and the field file's float grids by name, sampled at
// output voxel centres, and their automatic ranges, all without arrays over the output volume.
#pragma once

#include "lic/Field.h"
#include "lic/OutputDomain.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <cmath>
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

/// A scalar grid prepared for sampling at many world positions: trilinear values, the position
/// clamped to the grid's active bounding box (as the velocity sampler does: the outer half voxel
/// repeats the edge value), from a dense copy of that box (like lic::VelocityField; ~5× faster
/// than a value accessor and BoxSampler). Read-only after construction: share it between threads.
class ScalarField
{
public:
    ScalarField() = default;
    /// @throw lic::InputError for a grid with no active voxels, or an active box of more than
    ///        2^28 voxels (crop or resample the field).
    explicit ScalarField(openvdb::FloatGrid::ConstPtr grid);
    explicit operator bool() const { return bool(mGrid); }
    const openvdb::FloatGrid& grid() const { return *mGrid; }

    float at(const openvdb::Vec3d& world) const
    {
        const openvdb::Vec3d idx = lic::AffineMap::apply(mWorldToIndex, world);
        double f[3];
        std::size_t o0[3], o1[3];
        for (int a = 0; a < 3; ++a) {
            const double x = std::clamp(idx[a], mLo[a], mHi[a]) - mLo[a];
            const double fl = std::floor(x);
            const int i = int(fl);
            f[a] = x - fl;
            o0[a] = std::size_t(i) * mStride[a];
            o1[a] = std::size_t(std::min(i + 1, mDim[a] - 1)) * mStride[a];
        }
        const float* d = mData.data();
        auto lerp = [](double u, double v, double t) { return u + (v - u) * t; };
        const double c00 = lerp(d[o0[0] + o0[1] + o0[2]], d[o0[0] + o0[1] + o1[2]], f[2]);
        const double c01 = lerp(d[o0[0] + o1[1] + o0[2]], d[o0[0] + o1[1] + o1[2]], f[2]);
        const double c10 = lerp(d[o1[0] + o0[1] + o0[2]], d[o1[0] + o0[1] + o1[2]], f[2]);
        const double c11 = lerp(d[o1[0] + o1[1] + o0[2]], d[o1[0] + o1[1] + o1[2]], f[2]);
        return float(lerp(lerp(c00, c01, f[1]), lerp(c10, c11, f[1]), f[0]));
    }

private:
    openvdb::FloatGrid::ConstPtr mGrid;
    openvdb::Mat4d mWorldToIndex;
    double mLo[3] = {}, mHi[3] = {};
    int mDim[3] = {};
    std::size_t mStride[3] = {};
    std::vector<float> mData;
};

/// Robust automatic range of a scalar: its 1st and 99th percentiles over the active output voxel
/// centres (non-finite values skipped; a constant scalar gives [v, v + 1]). Exact order
/// statistics from two passes of a 65 536-bin histogram over the values' order-preserving bits,
/// so memory does not grow with the volume; deterministic for any thread count.
std::array<double, 2> autoRange(const ScalarField& scalar, const lic::OutputDomain& domain, int threads);

} // namespace vdbexport::pipeline

// A world-space velocity field on an OpenVDB Vec3 grid, with fast trilinear sampling.
#pragma once

#include "lic/util/IndexMath.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <vector>

namespace lic {

/// An affine index↔world map, extracted once from a linear openvdb::math::Transform so the
/// integrator's inner loop does not go through the transform's virtual map.
struct AffineMap
{
    openvdb::Mat4d indexToWorld;
    openvdb::Mat4d worldToIndex;

    AffineMap() = default;
    /// @throw lic::InputError if the transform is not linear (e.g. a frustum map).
    explicit AffineMap(const openvdb::math::Transform& xform);

    openvdb::Vec3d toIndex(const openvdb::Vec3d& w) const { return apply(worldToIndex, w); }
    openvdb::Vec3d toWorld(const openvdb::Vec3d& i) const { return apply(indexToWorld, i); }

    /// p·M for an affine matrix in OpenVDB's row-vector layout (no homogeneous divide).
    static openvdb::Vec3d apply(const openvdb::Mat4d& m, const openvdb::Vec3d& p)
    {
        return openvdb::Vec3d(p[0] * m[0][0] + p[1] * m[1][0] + p[2] * m[2][0] + m[3][0],
                              p[0] * m[0][1] + p[1] * m[1][1] + p[2] * m[2][1] + m[3][1],
                              p[0] * m[0][2] + p[1] * m[1][2] + p[2] * m[2][2] + m[3][2]);
    }
};

/// What a VelocityField that holds only part of a field must know about the whole field (a rank's
/// share of a distributed bake): its domain and zero-velocity threshold are the whole field's, so
/// streamlines stop where they would in the whole field and the result is bit-identical.
struct FieldExtent
{
    openvdb::CoordBBox activeBox;  ///< the whole field's active bounding box, index space, inclusive
    openvdb::Index64 activeVoxels = 0; ///< the whole field's active voxels
    double maxSpeed = 0.0;         ///< the whole field's largest |v|, world units per time
    /// The part held, index space: values are copied over region ∩ activeBox only, and positions
    /// outside it are clamped to it, so the caller must hold every voxel its traces can reach
    /// (plus one for the trilinear footprint).
    openvdb::CoordBBox region;
};

/// The velocity field of a bake: a Vec3 grid whose values are world-space vectors, placed in the
/// world by the grid's transform.
///
/// The domain is the extent of the grid's active voxels: a point is inside when its index-space
/// position lies within [min − 0.5, max + 0.5] of the active bounding box on every axis. Inside
/// the domain the field is interpolated trilinearly (cell-centred grids) or per face component
/// (staggered grids, GRID_STAGGERED); in the outermost half voxel the nearest voxel centre's
/// values are used. Inactive voxels inside the bounding box hold the background (normally zero),
/// so streamlines stop there.
class VelocityField
{
public:
    using Ptr = std::shared_ptr<const VelocityField>;

    /// @param grid the field; values are world-space vectors.
    /// @throw lic::InputError if the grid has no active voxels, a non-linear transform, NaN or
    ///        infinite values (the message counts them and names the first voxel), or is zero
    ///        everywhere.
    explicit VelocityField(openvdb::Vec3SGrid::ConstPtr grid);
    /// A part of a larger field (see FieldExtent): `grid` holds at least the active voxels of
    /// `whole.region` (e.g. read clipped to it); indexBBox(), the domain, maxSpeed() and
    /// activeVoxelCount() are the whole field's.
    /// @throw lic::InputError for NaN or infinite values in `grid`, a region that misses the
    ///        whole field's active box, or a whole field that is empty or zero everywhere.
    VelocityField(openvdb::Vec3SGrid::ConstPtr grid, const FieldExtent& whole);

    const openvdb::Vec3SGrid& grid() const { return *mGrid; }
    const openvdb::math::Transform& transform() const { return mGrid->transform(); }
    const AffineMap& map() const { return mMap; }
    bool isStaggered() const { return mStaggered; }

    /// Bounding box of the active voxels, index space, inclusive.
    const openvdb::CoordBBox& indexBBox() const { return mBBox; }
    /// World-space bounds of the active voxels' extents (index bbox ± half a voxel, mapped).
    openvdb::BBoxd worldBBox() const;
    /// Edge lengths of one voxel in world units.
    openvdb::Vec3d voxelSize() const { return mGrid->voxelSize(); }
    /// Largest speed |v| over active voxels (world units per time).
    double maxSpeed() const { return mMaxSpeed; }
    /// Number of active voxels.
    openvdb::Index64 activeVoxelCount() const { return mActiveVoxels; }

    /// True if a world position lies inside the domain (see class comment).
    bool contains(const openvdb::Vec3d& world) const { return containsIndex(mMap.toIndex(world)); }
    [[gnu::always_inline]] bool containsIndex(const openvdb::Vec3d& idx) const
    {
        return idx[0] >= mLo[0] && idx[1] >= mLo[1] && idx[2] >= mLo[2] && idx[0] <= mHi[0] &&
               idx[1] <= mHi[1] && idx[2] <= mHi[2];
    }

    /// Velocity (world units) at a world position. Returns false, leaving `v` untouched, when the
    /// position is outside the domain. Thread-safe; no allocation.
    bool sample(const openvdb::Vec3d& world, openvdb::Vec3d& v) const
    {
        const openvdb::Vec3d idx = mMap.toIndex(world);
        if (!containsIndex(idx)) return false;
        v = mStaggered ? sampleStaggered(idx) : sampleCentred(idx);
        return true;
    }

    /// Velocity and its world-space Jacobian dv[a][b] = ∂v_a/∂x_b (the derivative of the
    /// trilinear interpolant) at a world position. False outside the domain.
    bool sampleGradient(const openvdb::Vec3d& world, openvdb::Vec3d& v, openvdb::Mat3d& dv) const;

    /// Trilinear velocity at an index-space position (clamped to the active bounding box).
    openvdb::Vec3d sampleIndex(const openvdb::Vec3d& idx) const
    {
        return mStaggered ? sampleStaggered(idx) : sampleCentred(idx);
    }

    /// Flow direction in INDEX space: for an index position inside the domain, `d` = W·v/|v|·sign,
    /// W the linear part of world→index, |v| the world speed; i.e. the index-space displacement
    /// per unit of world arc length. False (d untouched) outside the domain or where |v| ≤
    /// minSpeed or is not finite. An index-space trace with these directions is the world-space
    /// trace mapped through the (affine) transform, without a transform per lookup.
    [[gnu::always_inline]] bool directionIndex(const openvdb::Vec3d& idx, double sign, double minSpeed,
                                               openvdb::Vec3d& d) const
    {
        if (!containsIndex(idx)) return false;
        const openvdb::Vec3d v = mStaggered ? sampleStaggered(idx) : sampleCentred(idx);
        const double len2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]; // Vec3::lengthSqr, always inlined
        if (!(len2 > minSpeed * minSpeed) || !std::isfinite(len2)) return false;
        const double s = sign / std::sqrt(len2);
        const openvdb::Mat4d& m = mMap.worldToIndex; // row-vector layout: d_j = Σ_i v_i m[i][j]
        d = openvdb::Vec3d((v[0] * m[0][0] + v[1] * m[1][0] + v[2] * m[2][0]) * s,
                           (v[0] * m[0][1] + v[1] * m[1][1] + v[2] * m[2][1]) * s,
                           (v[0] * m[0][2] + v[1] * m[1][2] + v[2] * m[2][2]) * s);
        return true;
    }

private:
    [[gnu::always_inline]] openvdb::Vec3d sampleCentred(const openvdb::Vec3d& idx) const;
    openvdb::Vec3d sampleStaggered(const openvdb::Vec3d& idx) const;
    /// Four floats (x, y, z, 0): one padded voxel, so the trilinear interpolation runs four lanes
    /// at a time.
    typedef float Float4 __attribute__((vector_size(16)));
    void init(const FieldExtent* whole);
    /// Value at integer coordinate, clamped to the bounding box (of the part held).
    openvdb::Vec3s at(int i, int j, int k) const
    {
        i = detail::clampIndex(i, mDenseBox.min()[0], mDenseBox.max()[0]) - mDenseBox.min()[0];
        j = detail::clampIndex(j, mDenseBox.min()[1], mDenseBox.max()[1]) - mDenseBox.min()[1];
        k = detail::clampIndex(k, mDenseBox.min()[2], mDenseBox.max()[2]) - mDenseBox.min()[2];
        const Float4& v = mData[(size_t(i) * mDim[1] + size_t(j)) * mDim[2] + size_t(k)];
        return openvdb::Vec3s(v[0], v[1], v[2]);
    }

    openvdb::Vec3SGrid::ConstPtr mGrid;
    AffineMap mMap;
    openvdb::Mat3d mIndexPerWorld; // linear part of world→index, for chain-rule derivatives
    bool mStaggered = false;
    openvdb::CoordBBox mBBox;     // active bounding box (of the whole field)
    openvdb::CoordBBox mDenseBox; // box of the dense copy: mBBox, or a part of it
    openvdb::Vec3d mLo, mHi;
    std::array<size_t, 3> mDim{};
    // Dense copy of the active bbox (z fastest, padded to four floats): the sampling fast path,
    // ~5x faster than a ValueAccessor + BoxSampler in the integrator loop. Allocated without
    // initialisation: every entry is written in parallel (the pages are first touched there).
    std::unique_ptr<Float4[]> mDense;
    const Float4* mData = nullptr;
    double mMaxSpeed = 0;
    openvdb::Index64 mActiveVoxels = 0;
};


[[gnu::always_inline]] inline openvdb::Vec3d VelocityField::sampleCentred(const openvdb::Vec3d& idx) const
{
    // idx lies in the active box (callers check containsIndex, or clamp), so floor fits an int.
    const int xi = detail::floorIndex(idx[0]), yi = detail::floorIndex(idx[1]), zi = detail::floorIndex(idx[2]);
    const double fx = idx[0] - double(xi), fy = idx[1] - double(yi), fz = idx[2] - double(zi);
    // Clamp each axis' two lattice indices once (as at() would per corner), then address the
    // eight corners by sums of per-axis offsets.
    const int i = xi - mDenseBox.min()[0], j = yi - mDenseBox.min()[1], k = zi - mDenseBox.min()[2];
    const int nx = int(mDim[0]) - 1, ny = int(mDim[1]) - 1, nz = int(mDim[2]) - 1;
    const std::size_t sx = mDim[1] * mDim[2], sy = mDim[2];
    using detail::clampIndex;
    const std::size_t x0 = std::size_t(clampIndex(i, 0, nx)) * sx, x1 = std::size_t(clampIndex(i + 1, 0, nx)) * sx;
    const std::size_t y0 = std::size_t(clampIndex(j, 0, ny)) * sy, y1 = std::size_t(clampIndex(j + 1, 0, ny)) * sy;
    const std::size_t z0 = std::size_t(clampIndex(k, 0, nz)), z1 = std::size_t(clampIndex(k + 1, 0, nz));
    const Float4* d = mData;
    const float tx = float(fx), ty = float(fy), tz = float(fz);
    const Float4 c00 = d[x0 + y0 + z0] + (d[x0 + y0 + z1] - d[x0 + y0 + z0]) * tz;
    const Float4 c01 = d[x0 + y1 + z0] + (d[x0 + y1 + z1] - d[x0 + y1 + z0]) * tz;
    const Float4 c10 = d[x1 + y0 + z0] + (d[x1 + y0 + z1] - d[x1 + y0 + z0]) * tz;
    const Float4 c11 = d[x1 + y1 + z0] + (d[x1 + y1 + z1] - d[x1 + y1 + z0]) * tz;
    const Float4 c0 = c00 + (c01 - c00) * ty, c1 = c10 + (c11 - c10) * ty;
    const Float4 v = c0 + (c1 - c0) * tx;
    return openvdb::Vec3d(v[0], v[1], v[2]);
}

} // namespace lic

#include "lic/field/Field.h"

#include "lic/util/Error.h"

#include <openvdb/tree/LeafManager.h>

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <sstream>

namespace lic {

AffineMap::AffineMap(const openvdb::math::Transform& xform)
{
    if (!xform.isLinear()) {
        throw InputError("field transform is not linear (map type " + xform.mapType() +
                         "); licvdb needs an affine index-to-world map");
    }
    indexToWorld = xform.baseMap()->getAffineMap()->getMat4();
    worldToIndex = indexToWorld.inverse();
}

namespace {

struct FieldScan
{
    openvdb::Index64 bad = 0;
    openvdb::Coord firstBad = openvdb::Coord::max();
    double maxSpeed = 0;
    void join(const FieldScan& o)
    {
        bad += o.bad;
        if (o.firstBad < firstBad) firstBad = o.firstBad;
        maxSpeed = std::max(maxSpeed, o.maxSpeed);
    }
};

FieldScan scanValues(const openvdb::Vec3SGrid& grid)
{
    openvdb::tree::LeafManager<const openvdb::Vec3STree> leaves(grid.tree());
    FieldScan leafScan = tbb::parallel_reduce(
        leaves.leafRange(), FieldScan{},
        [](const auto& range, FieldScan acc) {
            for (auto leaf = range.begin(); leaf; ++leaf) {
                for (auto it = leaf->cbeginValueOn(); it; ++it) {
                    const openvdb::Vec3s& v = *it;
                    if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) {
                        ++acc.bad;
                        if (it.getCoord() < acc.firstBad) acc.firstBad = it.getCoord();
                        continue;
                    }
                    acc.maxSpeed = std::max(acc.maxSpeed, double(v.length()));
                }
            }
            return acc;
        },
        [](FieldScan a, const FieldScan& b) {
            a.join(b);
            return a;
        });
    // Active tiles (constant regions) are not in the leaf manager.
    for (auto it = grid.tree().cbeginValueOn(); it; ++it) {
        if (it.isVoxelValue()) continue;
        const openvdb::Vec3s& v = *it;
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) {
            leafScan.bad += it.getVoxelCount();
            if (it.getCoord() < leafScan.firstBad) leafScan.firstBad = it.getCoord();
        } else {
            leafScan.maxSpeed = std::max(leafScan.maxSpeed, double(v.length()));
        }
    }
    return leafScan;
}

} // namespace

VelocityField::VelocityField(openvdb::Vec3SGrid::ConstPtr grid)
    : mGrid(std::move(grid))
{
    init(nullptr);
}

VelocityField::VelocityField(openvdb::Vec3SGrid::ConstPtr grid, const FieldExtent& whole)
    : mGrid(std::move(grid))
{
    init(&whole);
}

void VelocityField::init(const FieldExtent* whole)
{
    if (!mGrid) throw InputError("no velocity grid given");
    const std::string name = mGrid->getName().empty() ? "velocity" : mGrid->getName();
    mActiveVoxels = whole ? whole->activeVoxels : mGrid->activeVoxelCount();
    if (mActiveVoxels == 0) {
        throw InputError("velocity grid \"" + name + "\" has no active voxels: nothing to convolve");
    }
    mMap = AffineMap(mGrid->transform());
    mStaggered = mGrid->getGridClass() == openvdb::GRID_STAGGERED;
    mIndexPerWorld = mMap.worldToIndex.getMat3().transpose(); // OpenVDB matrices act on row vectors

    const FieldScan scan = scanValues(*mGrid);
    if (scan.bad > 0) {
        std::ostringstream msg;
        msg << "velocity grid \"" << name << "\" has " << scan.bad
            << " NaN or infinite values (first at voxel " << scan.firstBad << ")";
        throw InputError(msg.str());
    }
    mMaxSpeed = whole ? whole->maxSpeed : scan.maxSpeed;
    if (!(mMaxSpeed > 0)) {
        throw InputError("velocity grid \"" + name + "\" is zero everywhere: no flow to show");
    }

    mBBox = whole ? whole->activeBox : mGrid->evalActiveVoxelBoundingBox();
    mDenseBox = mBBox;
    if (whole) {
        mDenseBox.intersect(whole->region);
        if (mDenseBox.empty()) {
            std::ostringstream msg;
            msg << "the part " << whole->region << " of velocity grid \"" << name
                << "\" misses its active bounding box " << mBBox;
            throw InputError(msg.str());
        }
    }
    const openvdb::Coord dim = mDenseBox.dim();
    const double voxels = double(dim[0]) * dim[1] * dim[2];
    constexpr double kMaxDenseVoxels = double(1u << 28);
    if (voxels > kMaxDenseVoxels) {
        std::ostringstream msg;
        msg << "velocity grid \"" << name << "\" has an active bounding box of " << dim[0] << "x"
            << dim[1] << "x" << dim[2] << " voxels (more than 2^28); crop or resample it"
            << (whole ? ", or share the bake among more processes (mpirun -np N)" : "");
        throw InputError(msg.str());
    }
    mDim = {size_t(dim[0]), size_t(dim[1]), size_t(dim[2])};
    mLo = mBBox.min().asVec3d() - openvdb::Vec3d(0.5);
    mHi = mBBox.max().asVec3d() + openvdb::Vec3d(0.5);
    {
        // copyToDense writes every voxel of the box (values, tiles, background), in parallel, so
        // neither array is filled first (a serial fill would also fault every page on one core).
        const std::size_t n = std::size_t(dim[0]) * std::size_t(dim[1]) * std::size_t(dim[2]);
        const std::unique_ptr<openvdb::Vec3s[]> staging(new openvdb::Vec3s[n]);
        openvdb::tools::Dense<openvdb::Vec3s, openvdb::tools::LayoutZYX> dense(mDenseBox, staging.get());
        openvdb::tools::copyToDense(*mGrid, dense);
        mDense.reset(new Float4[n]);
        const openvdb::Vec3s* src = dense.data();
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const auto& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) mDense[i] = Float4{src[i][0], src[i][1], src[i][2], 0.0f};
        });
    }
    mData = mDense.get();
}

openvdb::BBoxd VelocityField::worldBBox() const
{
    return transform().indexToWorld(openvdb::BBoxd(mLo, mHi));
}

bool VelocityField::sampleGradient(const openvdb::Vec3d& world, openvdb::Vec3d& v,
                                   openvdb::Mat3d& dv) const
{
    const openvdb::Vec3d idx = mMap.toIndex(world);
    if (!containsIndex(idx)) return false;
    openvdb::Mat3d dIdx; // ∂v_a/∂idx_b
    for (int c = 0; c < 3; ++c) {
        openvdb::Vec3d p = idx;
        if (mStaggered) p[c] += 0.5;
        const int i = detail::floorIndex(p[0]), j = detail::floorIndex(p[1]), k = detail::floorIndex(p[2]);
        const double fx = p[0] - double(i), fy = p[1] - double(j), fz = p[2] - double(k);
        double n[2][2][2];
        for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b)
                for (int d = 0; d < 2; ++d) n[a][b][d] = at(i + a, j + b, k + d)[c];
        auto lerp = [](double u, double w, double t) { return u + (w - u) * t; };
        const double c00 = lerp(n[0][0][0], n[0][0][1], fz), c01 = lerp(n[0][1][0], n[0][1][1], fz);
        const double c10 = lerp(n[1][0][0], n[1][0][1], fz), c11 = lerp(n[1][1][0], n[1][1][1], fz);
        const double c0 = lerp(c00, c01, fy), c1 = lerp(c10, c11, fy);
        v[c] = lerp(c0, c1, fx);
        dIdx[c][0] = c1 - c0;
        dIdx[c][1] = lerp(c01 - c00, c11 - c10, fx);
        dIdx[c][2] = lerp(lerp(n[0][0][1] - n[0][0][0], n[0][1][1] - n[0][1][0], fy),
                          lerp(n[1][0][1] - n[1][0][0], n[1][1][1] - n[1][1][0], fy), fx);
    }
    // Chain rule: ∂v/∂x = ∂v/∂idx · ∂idx/∂x. Clamped (outer half voxel) axes have zero derivative
    // in the true interpolant; keeping the interior slope there is harmless for transport.
    dv = dIdx * mIndexPerWorld;
    return true;
}

openvdb::Vec3d VelocityField::sampleStaggered(const openvdb::Vec3d& idx) const
{
    // Component c of voxel (i,j,k) sits on the face at index position (i,j,k) − ½·e_c, so sample
    // that component at idx + ½·e_c on the voxel lattice (as openvdb::tools::StaggeredBoxSampler).
    openvdb::Vec3d out;
    for (int c = 0; c < 3; ++c) {
        openvdb::Vec3d p = idx;
        p[c] += 0.5;
        const int i = detail::floorIndex(p[0]), j = detail::floorIndex(p[1]), k = detail::floorIndex(p[2]);
        const double fx = p[0] - double(i), fy = p[1] - double(j), fz = p[2] - double(k);
        auto v = [&](int a, int b, int d) { return double(at(i + a, j + b, k + d)[c]); };
        const double c00 = v(0, 0, 0) + (v(0, 0, 1) - v(0, 0, 0)) * fz;
        const double c01 = v(0, 1, 0) + (v(0, 1, 1) - v(0, 1, 0)) * fz;
        const double c10 = v(1, 0, 0) + (v(1, 0, 1) - v(1, 0, 0)) * fz;
        const double c11 = v(1, 1, 0) + (v(1, 1, 1) - v(1, 1, 0)) * fz;
        const double c0 = c00 + (c01 - c00) * fy, c1 = c10 + (c11 - c10) * fy;
        out[c] = c0 + (c1 - c0) * fx;
    }
    return out;
}

} // namespace lic

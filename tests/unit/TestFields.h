// Small analytic fields for unit tests, built directly (independent of lic/field/Presets.h).
#pragma once

#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <functional>
#include <vector>

namespace lictest {

/// A dense Vec3S grid of res³ voxels, voxel size h, voxel (0,0,0) centred at `origin` (world),
/// filled with f(world position).
inline openvdb::Vec3SGrid::Ptr makeField(const openvdb::Coord& res, double h, const openvdb::Vec3d& origin,
                                         const std::function<openvdb::Vec3d(const openvdb::Vec3d&)>& f)
{
    openvdb::initialize();
    auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    auto xform = openvdb::math::Transform::createLinearTransform(h);
    xform->postTranslate(origin);
    grid->setTransform(xform);
    grid->setName("velocity");
    auto acc = grid->getAccessor();
    for (int i = 0; i < res[0]; ++i)
        for (int j = 0; j < res[1]; ++j)
            for (int k = 0; k < res[2]; ++k) {
                const openvdb::Coord ijk(i, j, k);
                acc.setValueOn(ijk, openvdb::Vec3s(f(xform->indexToWorld(ijk))));
            }
    return grid;
}

/// Solid-body rotation about +z through the origin, Ω = 1, on [−1, 1]³ with n³ voxels.
inline openvdb::Vec3SGrid::Ptr rotationField(int n = 41)
{
    const double h = 2.0 / (n - 1);
    return makeField(openvdb::Coord(n), h, openvdb::Vec3d(-1.0),
                     [](const openvdb::Vec3d& p) { return openvdb::Vec3d(-p[1], p[0], 0.0); });
}

/// Uniform flow along +x on [−1, 1]³ with n³ voxels.
inline openvdb::Vec3SGrid::Ptr uniformField(int n = 21, const openvdb::Vec3d& v = {1, 0, 0})
{
    const double h = 2.0 / (n - 1);
    return makeField(openvdb::Coord(n), h, openvdb::Vec3d(-1.0),
                     [v](const openvdb::Vec3d&) { return v; });
}

/// Arnold–Beltrami–Childress flow (A=√3, B=√2, C=1) on [0, 2π]³ with n³ voxels.
inline openvdb::Vec3SGrid::Ptr abcField(int n = 32)
{
    const double h = 2.0 * M_PI / (n - 1);
    const double A = std::sqrt(3.0), B = std::sqrt(2.0), C = 1.0;
    return makeField(openvdb::Coord(n), h, openvdb::Vec3d(0.0), [=](const openvdb::Vec3d& p) {
        return openvdb::Vec3d(A * std::sin(p[2]) + C * std::cos(p[1]),
                              B * std::sin(p[0]) + A * std::cos(p[2]),
                              C * std::sin(p[1]) + B * std::cos(p[0]));
    });
}

/// Mean of a slot-indexed volume over a domain's active slots (lic::OutputDomain).
template<typename Domain>
double meanOverActive(const Domain& d, const std::vector<float>& v)
{
    double s = 0, n = 0;
    for (std::size_t i = 0; i < v.size(); ++i)
        if (d.isActive(i)) s += v[i], n += 1;
    return s / n;
}

} // namespace lictest

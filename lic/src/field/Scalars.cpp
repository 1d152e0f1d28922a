#include "lic/field/Scalars.h"

#include "lic/util/Error.h"

#include <openvdb/tree/LeafManager.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace lic {

namespace {

using openvdb::Coord;
using openvdb::Mat3d;
using openvdb::Vec3d;

enum class Derived { Speed, Vorticity, StreamwiseVorticity, Helicity, QCriterion, Lambda2 };

std::string joined(const std::vector<std::string>& names)
{
    std::string out;
    for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
    return out;
}

/// Cell-centred velocity at active voxels of a (possibly staggered) Vec3 grid. One per thread.
class CentredVelocity
{
public:
    explicit CentredVelocity(const openvdb::Vec3SGrid& grid)
        : mAcc(grid.getConstAccessor())
        , mStaggered(grid.getGridClass() == openvdb::GRID_STAGGERED)
    {
    }

    /// The velocity at voxel centre @a ijk; false (leaving @a v untouched) if @a ijk is inactive.
    bool get(const Coord& ijk, Vec3d& v)
    {
        openvdb::Vec3s s;
        if (!mAcc.probeValue(ijk, s)) return false;
        v = Vec3d(s);
        if (mStaggered) {
            // Component c sits on the face ijk − ½e_c; average it with the face ijk + ½e_c.
            for (int c = 0; c < 3; ++c) {
                openvdb::Vec3s next;
                if (mAcc.probeValue(ijk.offsetBy(c == 0, c == 1, c == 2), next))
                    v[c] = 0.5 * (v[c] + next[c]);
            }
        }
        return true;
    }

    /// Index-space derivative ∂v/∂i_axis at active voxel @a ijk with velocity @a v: central where
    /// both neighbours are active, else one-sided (second order if possible), else zero.
    Vec3d indexDerivative(const Coord& ijk, const Vec3d& v, int axis)
    {
        const Coord e(axis == 0, axis == 1, axis == 2);
        Vec3d vp, vm, v2;
        const bool plus = get(ijk + e, vp), minus = get(ijk - e, vm);
        if (plus && minus) return 0.5 * (vp - vm);
        if (plus) return get(ijk + e + e, v2) ? 0.5 * (-3.0 * v + 4.0 * vp - v2) : vp - v;
        if (minus) return get(ijk - e - e, v2) ? 0.5 * (3.0 * v - 4.0 * vm + v2) : v - vm;
        return Vec3d(0.0);
    }

private:
    openvdb::Vec3SGrid::ConstAccessor mAcc;
    bool mStaggered;
};

/// World-space velocity gradient J[a][b] = ∂v_a/∂x_b at active voxel @a ijk.
Mat3d worldJacobian(CentredVelocity& vel, const openvdb::math::MapBase& map, const Coord& ijk,
                    const Vec3d& v)
{
    Mat3d dIndex; // dIndex[a][b] = ∂v_a/∂i_b
    for (int b = 0; b < 3; ++b) {
        const Vec3d d = vel.indexDerivative(ijk, v, b);
        for (int a = 0; a < 3; ++a) dIndex[a][b] = d[a];
    }
    Mat3d J;
    for (int a = 0; a < 3; ++a) {
        // Chain rule for the gradient of component a: ∇_world = J_map^{-T} ∇_index.
        const Vec3d g = map.applyIJT(Vec3d(dIndex[a][0], dIndex[a][1], dIndex[a][2]), ijk.asVec3d());
        for (int b = 0; b < 3; ++b) J[a][b] = g[b];
    }
    return J;
}

/// Jeong & Hussain's λ2: the middle eigenvalue of S² + Ω² (symmetric), by the closed-form
/// trigonometric solution for 3×3 symmetric matrices. λ2 < 0 inside a vortex core.
double lambda2(const Mat3d& J)
{
    Mat3d S, W;
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
            S[a][b] = 0.5 * (J[a][b] + J[b][a]);
            W[a][b] = 0.5 * (J[a][b] - J[b][a]);
        }
    const Mat3d M = S * S + W * W;
    const double p1 = M[0][1] * M[0][1] + M[0][2] * M[0][2] + M[1][2] * M[1][2];
    const double q = (M[0][0] + M[1][1] + M[2][2]) / 3.0;
    const double p2 = (M[0][0] - q) * (M[0][0] - q) + (M[1][1] - q) * (M[1][1] - q) +
                      (M[2][2] - q) * (M[2][2] - q) + 2.0 * p1;
    if (p2 <= 1e-30 * (1.0 + q * q)) return q; // isotropic: all eigenvalues equal
    const double p = std::sqrt(p2 / 6.0);
    Mat3d B = M;
    for (int a = 0; a < 3; ++a) B[a][a] -= q;
    B *= 1.0 / p;
    const double r = std::clamp(B.det() / 2.0, -1.0, 1.0);
    const double phi = std::acos(r) / 3.0;
    const double largest = q + 2.0 * p * std::cos(phi);
    const double smallest = q + 2.0 * p * std::cos(phi + 2.0 * M_PI / 3.0);
    return 3.0 * q - largest - smallest;
}

double evaluate(Derived kind, const Vec3d& v, const Mat3d& J)
{
    const Vec3d omega(J[2][1] - J[1][2], J[0][2] - J[2][0], J[1][0] - J[0][1]);
    switch (kind) {
    case Derived::Speed: return v.length();
    case Derived::Vorticity: return omega.length();
    case Derived::StreamwiseVorticity: {
        const double speed = v.length();
        return speed > 0.0 ? omega.dot(v) / speed : 0.0;
    }
    case Derived::Helicity: return omega.dot(v);
    case Derived::QCriterion: {
        // ‖Ω‖² − ‖S‖² = Σ_ab (Ω_ab² − S_ab²) = −Σ_ab J_ab J_ba, so Q = −½ tr(J²).
        double trJ2 = 0.0;
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) trJ2 += J[a][b] * J[b][a];
        return -0.5 * trJ2;
    }
    case Derived::Lambda2: return lambda2(J);
    }
    return 0.0;
}

} // namespace

const std::vector<std::string>& derivedScalarNames()
{
    // Order matches enum Derived.
    static const std::vector<std::string> names = {"speed", "vorticity", "streamwise-vorticity",
                                                   "helicity", "q-criterion", "lambda2"};
    return names;
}

openvdb::FloatGrid::Ptr deriveScalar(const openvdb::Vec3SGrid& velocity, const std::string& name)
{
    const auto& names = derivedScalarNames();
    const auto found = std::find(names.begin(), names.end(), name);
    if (found == names.end()) {
        throw InputError("unknown scalar '" + name + "': derived scalars are " + joined(names) +
                         "; the name of a float grid in the field file can also be given");
    }
    const auto kind = Derived(found - names.begin());

    // Same active topology as the velocity, with every active value in a leaf voxel.
    auto tree = std::make_shared<openvdb::FloatTree>(velocity.tree(), 0.0f, openvdb::TopologyCopy());
    tree->voxelizeActiveTiles();
    auto out = openvdb::FloatGrid::create(tree);
    out->setTransform(velocity.transform().copy());
    out->setName(name);
    out->setGridClass(openvdb::GRID_UNKNOWN);

    const openvdb::math::MapBase& map = *velocity.transform().baseMap();
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(*tree);
    tbb::parallel_for(leaves.leafRange(), [&](const auto& range) {
        CentredVelocity vel(velocity);
        for (auto leaf = range.begin(); leaf; ++leaf) {
            for (auto it = leaf->beginValueOn(); it; ++it) {
                Vec3d v(0.0);
                vel.get(it.getCoord(), v);
                const Mat3d J = kind == Derived::Speed
                                    ? Mat3d::zero()
                                    : worldJacobian(vel, map, it.getCoord(), v);
                it.setValue(float(evaluate(kind, v, J)));
            }
        }
    });
    return out;
}

openvdb::FloatGrid::ConstPtr resolveScalar(
    const openvdb::Vec3SGrid& velocity,
    const std::map<std::string, openvdb::FloatGrid::Ptr>& fileScalars, const std::string& name)
{
    const auto& names = derivedScalarNames();
    if (std::find(names.begin(), names.end(), name) != names.end())
        return deriveScalar(velocity, name);
    if (auto it = fileScalars.find(name); it != fileScalars.end() && it->second) return it->second;

    std::vector<std::string> fileNames;
    for (const auto& [key, grid] : fileScalars)
        if (grid) fileNames.push_back(key);
    throw InputError("unknown scalar '" + name + "': derived scalars are " + joined(names) +
                     "; float grids in the field file are " +
                     (fileNames.empty() ? std::string("(none)") : joined(fileNames)));
}

} // namespace lic

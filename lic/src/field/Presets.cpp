// Analytic example vector fields baked into OpenVDB grids (see lic/field/Presets.h).
//
// Every formula below is in world units and is evaluated at the voxel centre's world
// position p = (x, y, z). Evaluation is done in double precision and stored as float.

#include "lic/field/Presets.h"

#include "lic/util/Error.h"

#include <openvdb/tree/LeafManager.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>

namespace lic {
namespace detail {

using openvdb::Vec3d;

constexpr double kPi = std::numbers::pi;

/// Static description of one preset: its world box and default resolution.
struct PresetInfo
{
    const char* name;
    const char* description;
    openvdb::Coord defaultResolution; ///< voxels (x, y, z)
    Vec3d centre;                     ///< world units: centre of the box of voxel centres
    double extent;                    ///< world units: span of voxel centres on the longest axis
};

const std::array<PresetInfo, 7>& presetTable()
{
    static const std::array<PresetInfo, 7> table{{
        {"uniform", "uniform flow v = (1,0,0) on [-1,1]^3",
         openvdb::Coord(64), Vec3d(0.0), 2.0},
        {"rotation", "solid-body rotation about +z, v = (-y,x,0), vorticity (0,0,2), on [-1,1]^3",
         openvdb::Coord(64), Vec3d(0.0), 2.0},
        {"abc", "Arnold-Beltrami-Childress flow (A=sqrt3, B=sqrt2, C=1), curl v = v, on [0,2pi]^3",
         openvdb::Coord(64), Vec3d(kPi), 2.0 * kPi},
        {"saddle", "3D stagnation-point flow v = (x,y,-2z), divergence free, on [-1,1]^3",
         openvdb::Coord(64), Vec3d(0.0), 2.0},
        {"tornado", "Crawfis's tornado (time 0): a swirling funnel rising along z, on [0,1]^3",
         openvdb::Coord(64), Vec3d(0.5), 1.0},
        {"vortex-ring", "vortex ring (radius 0.5, Lamb-Oseen core 0.15) threaded by a +z drift, on [-1,1]^3",
         openvdb::Coord(64), Vec3d(0.0), 2.0},
        {"tabbed-jet", "lobed axial jet along +z with 4 pairs of counter-rotating streamwise "
                       "vortices, plus a temperature grid (K); z in [0,2]",
         openvdb::Coord(101, 101, 148), Vec3d(0.0, 0.0, 1.0), 2.0},
    }};
    return table;
}

std::string validNamesList()
{
    std::string list;
    for (const auto& info : presetTable()) {
        if (!list.empty()) list += ", ";
        list += info.name;
    }
    return list;
}

const PresetInfo& findPreset(const std::string& name)
{
    for (const auto& info : presetTable()) {
        if (name == info.name) return info;
    }
    throw InputError("unknown field preset '" + name + "'; expected one of: " + validNamesList());
}

void validateResolution(const openvdb::Coord& res)
{
    constexpr int kMinRes = 2, kMaxRes = 2048;
    constexpr std::uint64_t kMaxVoxels = std::uint64_t(1) << 30;
    const std::string text = std::to_string(res.x()) + "," + std::to_string(res.y()) + "," +
                             std::to_string(res.z());
    for (int axis = 0; axis < 3; ++axis) {
        if (res[axis] < kMinRes || res[axis] > kMaxRes) {
            throw InputError("field resolution " + text + " has " + std::to_string(res[axis]) +
                             " voxels on axis " + "xyz"[axis] + "; expected " +
                             std::to_string(kMinRes) + " to " + std::to_string(kMaxRes) +
                             " per axis");
        }
    }
    const std::uint64_t total =
        std::uint64_t(res.x()) * std::uint64_t(res.y()) * std::uint64_t(res.z());
    if (total > kMaxVoxels) {
        throw InputError("field resolution " + text + " has " + std::to_string(total) +
                         " voxels; expected at most 2^30 = " + std::to_string(kMaxVoxels));
    }
}

/// In-plane velocity of a 2D Lamb-Oseen vortex at offset d = p - centre (world units):
/// u = Γ/(2π|d|²) (1 - exp(-|d|²/a²)) (-d_y, d_x), counter-clockwise for Γ > 0.
/// Finite at the core centre (u -> Γ/(2πa²) (-d_y, d_x) as |d| -> 0).
openvdb::Vec2d lambOseen(double dx, double dy, double gamma, double a)
{
    const double s2 = dx * dx + dy * dy;
    const double a2 = a * a;
    const double f = s2 > 0.0 ? -std::expm1(-s2 / a2) / s2 : 1.0 / a2;
    const double k = gamma / (2.0 * kPi) * f;
    return {-k * dy, k * dx};
}

// ---- velocity formulas (world units) ------------------------------------------------

/// uniform: v = (1, 0, 0).
Vec3d uniformVelocity(const Vec3d&) { return {1.0, 0.0, 0.0}; }

/// rotation: solid-body rotation about +z with Ω = 1: v = (-y, x, 0); curl v = (0, 0, 2Ω).
Vec3d rotationVelocity(const Vec3d& p) { return {-p.y(), p.x(), 0.0}; }

/// abc: v = (A sin z + C cos y, B sin x + A cos z, C sin y + B cos x), A = √3, B = √2, C = 1.
/// A Beltrami field: curl v = v, helicity v·curl v = |v|².
Vec3d abcVelocity(const Vec3d& p)
{
    const double a = std::sqrt(3.0), b = std::sqrt(2.0), c = 1.0;
    const double x = p.x(), y = p.y(), z = p.z();
    return {a * std::sin(z) + c * std::cos(y), b * std::sin(x) + a * std::cos(z),
            c * std::sin(y) + b * std::cos(x)};
}

/// saddle: 3D stagnation-point flow v = (x, y, -2z): divergence free, zero at the origin.
Vec3d saddleVelocity(const Vec3d& p) { return {p.x(), p.y(), -2.0 * p.z()}; }

/// tornado: Roger Crawfis's tornado (gen_tornado, time = 0) on [0,1]^3:
///   xc = 0.5 + 0.1 sin(10 z), yc = 0.5 + 0.1 cos(3 z)        (centre of the funnel)
///   r = 0.1 + 0.4 z² + 0.1 z sin(8 z), r2 = 0.2 + 0.1 z       (funnel radius, damping)
///   t = hypot(x - xc, y - yc); s = |r - t|; s = (s > r2) ? 0.8 - s : 1
///   z0 = max(0, 0.1 (0.1 - t z)); t = sqrt(t² + z0²)
///   s = (r + r2 - t) s / (t + 1e-11) / (1 + z)
///   v = (s (y - yc) + 0.1 (x - xc), -s (x - xc) + 0.1 (y - yc), s z0)
/// (The magnitude jumps where |r - t| = r2, as in the original.)
Vec3d tornadoVelocityAt(const Vec3d& p, double time)
{
    const double x = p.x(), y = p.y(), z = p.z();
    // Crawfis's time term (0.04 and 0.03 per step) at 25 steps per time unit.
    const double xc = 0.5 + 0.1 * std::sin(1.0 * time + 10.0 * z);
    const double yc = 0.5 + 0.1 * std::cos(0.75 * time + 3.0 * z);
    const double r = 0.1 + 0.4 * z * z + 0.1 * z * std::sin(8.0 * z);
    const double r2 = 0.2 + 0.1 * z;
    double temp = std::hypot(x - xc, y - yc);
    double scale = std::abs(r - temp);
    scale = (scale > r2) ? 0.8 - scale : 1.0;
    const double z0 = std::max(0.0, 0.1 * (0.1 - temp * z));
    temp = std::sqrt(temp * temp + z0 * z0);
    scale = (r + r2 - temp) * scale / (temp + 1e-11);
    scale /= (1.0 + z);
    return {scale * (y - yc) + 0.1 * (x - xc), -scale * (x - xc) + 0.1 * (y - yc), scale * z0};
}

Vec3d tornadoVelocity(const Vec3d& p) { return tornadoVelocityAt(p, 0.0); }

/// vortex-ring: one vortex ring of radius R = 0.5 in the plane z = 0, Lamb-Oseen core of
/// radius a = 0.15, circulation Γ = 1. With ρ = hypot(x, y), d = (d_ρ, d_z) = (ρ - R, z),
/// r = |d|, the meridional (ρ, z) velocity swirls around the core circle:
///   u_merid = Γ/(2π r) (1 - exp(-r²/a²)) (-d_z, d_ρ)/r,
/// its ρ component rotated back to (x, y) by the azimuth, plus a uniform drift
/// 0.05 Γ/R = 0.1 along +z so that streamlines thread the ring instead of closing.
/// On the axis (ρ = 0) the radial part is dropped (it vanishes there by symmetry).
Vec3d vortexRingVelocity(const Vec3d& p)
{
    constexpr double kRadius = 0.5, kCore = 0.15, kGamma = 1.0;
    constexpr double kDrift = 0.05 * kGamma / kRadius;
    const double rho = std::hypot(p.x(), p.y());
    // lambOseen(dρ, dz) returns k (-d_z, d_ρ): exactly (u_ρ, u_z).
    // Negative circulation in the (ρ, z) plane: the ring's own flow goes +z through its middle
    // and −z outside it, as for a ring travelling along +z (the direction of the drift).
    const openvdb::Vec2d u = lambOseen(rho - kRadius, p.z(), -kGamma, kCore);
    const double ex = rho > 0.0 ? p.x() / rho : 0.0;
    const double ey = rho > 0.0 ? p.y() / rho : 0.0;
    return {u[0] * ex, u[0] * ey, u[1] + kDrift};
}

// ---- tabbed jet ----------------------------------------------------------------------
// An axial jet along +z with four tabs at its nozzle (after Interrante & Grosch's data):
//   R(z) = 0.3 (1 + 0.25 z)                        jet radius (spreads downstream)
//   θ = atan2(y, x), r = hypot(x, y)
//   g(z) = clamp(z, 0, 1)                          lobe growth
//   r_eff = r (1 - 0.12 cos(4θ) g(z))              four lobes, at θ = kπ/2
//   w = 0.1 + 0.9 · ½(1 - tanh((r_eff - R)/δ)) / (1 + 0.3 z),   δ = 0.05 (co-flow 0.1)
// Eight streamwise Lamb-Oseen vortices at radius R(z), angles θ_k ± 0.22 (k = 0..3),
// core radius a = 0.06 (1 + 0.5 z), circulation Γ = ±0.25 exp(-0.4 z): the one at
// θ_k + 0.22 turns counter-clockwise (Γ > 0), the one at θ_k - 0.22 clockwise, so each
// pair pumps fluid radially outward between its members, into the lobe at θ_k.
// Temperature (kelvin): T = 300 + 60 · ½(1 - tanh((r_eff - R)/δ_T)) / (1 + 0.5 z),
// δ_T = 0.07 (a hot jet core in 300 K surroundings).

constexpr double kJetTabAngle = 0.22;    // rad, half the angular spacing of a vortex pair
constexpr double kJetGamma = 0.25;       // world units²/time, circulation at z = 0

double jetRadius(double z) { return 0.3 * (1.0 + 0.25 * z); }

/// ½(1 - tanh((r_eff - R(z))/δ)): 1 inside the lobed jet, 0 outside, edge width δ.
double jetProfile(const Vec3d& p, double delta)
{
    const double r = std::hypot(p.x(), p.y());
    const double theta = std::atan2(p.y(), p.x()); // atan2(0, 0) = 0: finite on the axis
    const double g = std::clamp(p.z(), 0.0, 1.0);
    const double rEff = r * (1.0 - 0.12 * std::cos(4.0 * theta) * g);
    return 0.5 * (1.0 - std::tanh((rEff - jetRadius(p.z())) / delta));
}

Vec3d tabbedJetVelocity(const Vec3d& p)
{
    const double z = p.z();
    const double w = 0.1 + 0.9 * jetProfile(p, 0.05) / (1.0 + 0.3 * z);
    const double radius = jetRadius(z);
    const double core = 0.06 * (1.0 + 0.5 * z);
    const double gamma = kJetGamma * std::exp(-0.4 * z);
    // Unit directions θ_k ± 0.22 and the sign of each vortex's circulation (constant).
    struct Tab { double cosA, sinA, sign; };
    static const std::array<Tab, 8> tabs = [] {
        std::array<Tab, 8> t{};
        for (int i = 0; i < 8; ++i) {
            const double sign = (i % 2 == 0) ? 1.0 : -1.0;
            const double angle = (i / 2) * 0.5 * kPi + sign * kJetTabAngle;
            t[i] = {std::cos(angle), std::sin(angle), sign};
        }
        return t;
    }();
    openvdb::Vec2d uv(0.0, 0.0);
    for (const Tab& tab : tabs) {
        uv += lambOseen(p.x() - radius * tab.cosA, p.y() - radius * tab.sinA,
                        tab.sign * gamma, core);
    }
    return {uv[0], uv[1], w};
}

double tabbedJetTemperature(const Vec3d& p)
{
    return 300.0 + 60.0 * jetProfile(p, 0.07) / (1.0 + 0.5 * p.z());
}

using VelocityFn = Vec3d (*)(const Vec3d&);

VelocityFn velocityFunction(const std::string& name)
{
    if (name == "uniform") return &uniformVelocity;
    if (name == "rotation") return &rotationVelocity;
    if (name == "abc") return &abcVelocity;
    if (name == "saddle") return &saddleVelocity;
    if (name == "tornado") return &tornadoVelocity;
    if (name == "vortex-ring") return &vortexRingVelocity;
    if (name == "tabbed-jet") return &tabbedJetVelocity;
    throw InputError("unknown field preset '" + name + "'; expected one of: " + validNamesList());
}

// ---- grid construction -----------------------------------------------------------------

/// Transform whose voxel centres, for index 0..res-1, span `extent` (world units) on the
/// longest axis and are centred on `centre`; voxel size h = extent/(maxRes-1) on all axes.
openvdb::math::Transform::Ptr presetTransform(const PresetInfo& info, const openvdb::Coord& res)
{
    const int maxRes = std::max({res.x(), res.y(), res.z()});
    const double h = info.extent / double(maxRes - 1);
    auto xform = openvdb::math::Transform::createLinearTransform(h);
    const Vec3d halfSpan(0.5 * h * (res.x() - 1), 0.5 * h * (res.y() - 1), 0.5 * h * (res.z() - 1));
    xform->postTranslate(info.centre - halfSpan);
    return xform;
}

/// Activate every voxel of [0, res-1] as a leaf voxel (no tiles), value zero.
template<typename GridT>
void activateBox(GridT& grid, const openvdb::Coord& res)
{
    const openvdb::CoordBBox box(openvdb::Coord(0), res - openvdb::Coord(1));
    grid.tree().denseFill(box, grid.background(), /*active=*/true);
    grid.tree().voxelizeActiveTiles(/*threaded=*/true);
}

/// Set every active voxel to fn(world position of its centre), in parallel over leaves.
/// Deterministic: each value depends only on its voxel's position.
template<typename GridT, typename Fn>
void fillFromWorld(GridT& grid, const Fn& fn)
{
    using ValueT = typename GridT::ValueType;
    const openvdb::math::Transform& xform = grid.transform();
    openvdb::tree::LeafManager<typename GridT::TreeType> leaves(grid.tree());
    tbb::parallel_for(leaves.leafRange(), [&](const auto& range) {
        for (auto leaf = range.begin(); leaf; ++leaf) {
            for (auto it = leaf->beginValueOn(); it; ++it) {
                it.setValue(ValueT(fn(xform.indexToWorld(it.getCoord()))));
            }
        }
    });
}

} // namespace detail

std::vector<std::string> presetNames()
{
    std::vector<std::string> names;
    for (const auto& info : detail::presetTable()) names.emplace_back(info.name);
    return names;
}

std::string presetDescription(const std::string& name)
{
    return detail::findPreset(name).description;
}

openvdb::Coord presetDefaultResolution(const std::string& name)
{
    return detail::findPreset(name).defaultResolution;
}

bool presetIsUnsteady(const std::string& name) { return detail::findPreset(name).name == std::string("tornado"); }

PresetField makePresetField(const std::string& name, const openvdb::Coord& resolution, double time)
{
    const detail::PresetInfo& info = detail::findPreset(name);
    detail::validateResolution(resolution);
    openvdb::initialize();

    const auto xform = detail::presetTransform(info, resolution);
    const auto steadyFn = detail::velocityFunction(name);
    const bool unsteady = presetIsUnsteady(name) && time != 0.0;
    auto velocityFn = [steadyFn, unsteady, time](const openvdb::Vec3d& p) {
        return unsteady ? detail::tornadoVelocityAt(p, time) : steadyFn(p);
    };

    PresetField field;
    field.velocity = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    field.velocity->setName("velocity");
    field.velocity->setTransform(xform);
    field.velocity->setGridClass(openvdb::GRID_UNKNOWN);
    field.velocity->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    field.velocity->setIsInWorldSpace(true);
    field.velocity->insertMeta("licvdb_preset", openvdb::StringMetadata(name));
    if (time != 0.0) field.velocity->insertMeta("licvdb_time", openvdb::DoubleMetadata(time));
    detail::activateBox(*field.velocity, resolution);
    detail::fillFromWorld(*field.velocity, [velocityFn](const openvdb::Vec3d& p) {
        return openvdb::Vec3s(velocityFn(p));
    });

    if (name == "tabbed-jet") {
        auto temperature = openvdb::FloatGrid::create(0.0f);
        temperature->setName("temperature");
        temperature->setTransform(xform->copy());
        temperature->insertMeta("licvdb_preset", openvdb::StringMetadata(name));
        temperature->insertMeta("units", openvdb::StringMetadata("K"));
        detail::activateBox(*temperature, resolution);
        detail::fillFromWorld(*temperature, [](const openvdb::Vec3d& p) {
            return float(detail::tabbedJetTemperature(p));
        });
        field.scalars.push_back(temperature);
    }
    return field;
}

} // namespace lic

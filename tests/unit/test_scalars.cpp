// Derived scalars against closed forms: solid-body rotation, ABC flow, uniform and linear flows.
#include "TestFields.h"

#include <lic/util/Error.h>
#include <lic/field/Presets.h>
#include <lic/field/ScalarField.h>
#include <lic/field/Scalars.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>

using openvdb::Coord;
using openvdb::Vec3d;

namespace {

/// Call f(ijk, world position, value) for every active voxel of @a grid.
void forEachActive(const openvdb::FloatGrid& grid,
                   const std::function<void(const Coord&, const Vec3d&, double)>& f)
{
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        ASSERT_TRUE(it.isVoxelValue()) << "active tile at " << it.getCoord();
        f(it.getCoord(), grid.transform().indexToWorld(it.getCoord()), *it);
    }
}

/// True if @a ijk is at least @a margin voxels inside the box [0, n−1] on every axis.
bool interior(const Coord& ijk, const Coord& n, int margin = 2)
{
    for (int a = 0; a < 3; ++a)
        if (ijk[a] < margin || ijk[a] > n[a] - 1 - margin) return false;
    return true;
}

/// A linear flow v = A p + b with every kind of gradient term (rotation, strain, shear).
const openvdb::Mat3d kA(0.3, -1.2, 0.5, //
                        0.8, -0.1, 0.7, //
                        -0.4, 0.2, -0.2);
const Vec3d kB(0.5, -0.25, 1.0);
Vec3d linearFlow(const Vec3d& p) { return kA * p + kB; }
/// curl of kA·p: ω = (A32 − A23, A13 − A31, A21 − A12) (rows a, columns b: A_ab = ∂v_a/∂x_b).
Vec3d linearCurl()
{
    return Vec3d(kA[2][1] - kA[1][2], kA[0][2] - kA[2][0], kA[1][0] - kA[0][1]);
}
/// Q = ½(‖Ω‖² − ‖S‖²) with S, Ω the symmetric and antisymmetric parts of A, computed the long way.
double linearQ()
{
    double omega2 = 0, strain2 = 0;
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
            const double s = 0.5 * (kA[a][b] + kA[b][a]), w = 0.5 * (kA[a][b] - kA[b][a]);
            strain2 += s * s;
            omega2 += w * w;
        }
    return 0.5 * (omega2 - strain2);
}

} // namespace

TEST(Scalars, NamesAreStable)
{
    const std::vector<std::string> expected = {"speed", "vorticity", "streamwise-vorticity",
                                               "helicity", "q-criterion", "lambda2"};
    EXPECT_EQ(lic::derivedScalarNames(), expected);
}

// v = (−y, x, 0): ∇v = [[0,−1,0],[1,0,0],[0,0,0]], so S = 0, Ω = ∇v, ‖Ω‖²_F = 2 and
// Q = ½(2 − 0) = 1; ω = (0, 0, 2), v·ω = 0. The field is linear, so the differences are exact
// everywhere, the one-sided ones at the boundary included: every voxel is checked.
TEST(Scalars, SolidBodyRotation)
{
    const auto vel = lictest::rotationField(41);
    const auto check = [&](const std::string& name, const std::function<double(const Vec3d&)>& f) {
        const auto s = lic::deriveScalar(*vel, name);
        EXPECT_EQ(s->getName(), name);
        EXPECT_EQ(s->getGridClass(), openvdb::GRID_UNKNOWN);
        EXPECT_EQ(s->activeVoxelCount(), vel->activeVoxelCount());
        forEachActive(*s, [&](const Coord& ijk, const Vec3d& p, double value) {
            EXPECT_NEAR(value, f(p), 1e-4) << name << " at " << ijk << " = " << p;
        });
    };
    check("vorticity", [](const Vec3d&) { return 2.0; });
    check("helicity", [](const Vec3d&) { return 0.0; });
    check("streamwise-vorticity", [](const Vec3d&) { return 0.0; });
    check("q-criterion", [](const Vec3d&) { return 1.0; });
    check("lambda2", [](const Vec3d&) { return -1.0; }); // S = 0, Ω² = diag(−1, −1, 0)
    check("speed", [](const Vec3d& p) { return std::hypot(p[0], p[1]); });
}

// ABC flow: curl v = v exactly. Every term is a unit-wavenumber sine along one axis, and the
// central difference of sin(x + φ) is (sin h / h)·cos(x + φ), so the discrete curl is exactly
// (sin h / h)·v: with h = 2π/47, 1 − sin h / h ≈ h²/6 ≈ 0.30 %. Interior voxels are checked
// against the continuous values to 0.5 % (the second-order truncation error, plus float
// rounding) and against the discrete values to 1e-4 (float rounding only).
// (openvdb::tools::curl agrees with these interior values to 5e-7 but is off by up to 13 at the
// boundary, where it differences against the zero background: hence our own differences.)
TEST(Scalars, AbcFlowCurlEqualsVelocity)
{
    const int n = 48;
    const auto vel = lictest::abcField(n);
    const double h = 2.0 * M_PI / (n - 1), ratio = std::sin(h) / h;
    const double A = std::sqrt(3.0), B = std::sqrt(2.0), C = 1.0;
    const auto exact = [=](const Vec3d& p) {
        return Vec3d(A * std::sin(p[2]) + C * std::cos(p[1]), B * std::sin(p[0]) + A * std::cos(p[2]),
                     C * std::sin(p[1]) + B * std::cos(p[0]));
    };
    const auto check = [&](const std::string& name, const std::function<double(double)>& ofSpeed,
                           double discreteFactor) {
        const auto s = lic::deriveScalar(*vel, name);
        int checked = 0;
        forEachActive(*s, [&](const Coord& ijk, const Vec3d& p, double value) {
            if (!interior(ijk, Coord(n))) return;
            const double expected = ofSpeed(exact(p).length());
            EXPECT_NEAR(value, expected, 0.005 * std::abs(expected) + 1e-5) << name << " at " << ijk;
            EXPECT_NEAR(value, discreteFactor * expected, 1e-4) << name << " at " << ijk;
            ++checked;
        });
        EXPECT_EQ(checked, (n - 4) * (n - 4) * (n - 4));
    };
    check("vorticity", [](double s) { return s; }, ratio);
    check("streamwise-vorticity", [](double s) { return s; }, ratio);
    check("helicity", [](double s) { return s * s; }, ratio);
    check("speed", [](double s) { return s; }, 1.0);

    // Boundary voxels use one-sided second-order differences: per term the error is at most
    // h²/3 (times the term's amplitude), so |ω_h − ω| ≤ h²/3 · |(A+C, B+A, C+B)| ≈ 0.029.
    const double bound = h * h / 3.0 * Vec3d(A + C, B + A, C + B).length();
    int boundary = 0;
    forEachActive(*lic::deriveScalar(*vel, "vorticity"), [&](const Coord& ijk, const Vec3d& p, double value) {
        if (interior(ijk, Coord(n))) return;
        EXPECT_NEAR(value, exact(p).length(), bound) << "boundary voxel " << ijk;
        ++boundary;
    });
    EXPECT_EQ(boundary, n * n * n - (n - 4) * (n - 4) * (n - 4));
}

// A uniform flow has zero gradient: every derived scalar but speed is 0, everywhere.
TEST(Scalars, UniformFlow)
{
    const auto vel = lictest::uniformField(21, Vec3d(0.6, 0.0, -0.8));
    for (const auto& name : lic::derivedScalarNames()) {
        const double expected = name == "speed" ? 1.0 : 0.0;
        forEachActive(*lic::deriveScalar(*vel, name), [&](const Coord& ijk, const Vec3d&, double value) {
            EXPECT_NEAR(value, expected, 1e-6) << name << " at " << ijk;
        });
    }
}

// λ2 of a pure strain v = (x, y, −2z): S = diag(1, 1, −2), Ω = 0, S² = diag(1, 1, 4) → λ2 = 1.
// A rotation plus a strain along the axis, v = (−y, x, 0) + (0, 0, z)·0.5 − (x, y, 0)·0.25:
// S = diag(−¼, −¼, ½), Ω² = diag(−1, −1, 0) → S² + Ω² = diag(−15/16, −15/16, ¼) → λ2 = −15/16.
TEST(Scalars, Lambda2ClosedForms)
{
    const auto strain = lictest::makeField(Coord(9), 0.25, Vec3d(-1.0),
                                           [](const Vec3d& p) { return Vec3d(p[0], p[1], -2.0 * p[2]); });
    const auto vortex = lictest::makeField(Coord(9), 0.25, Vec3d(-1.0), [](const Vec3d& p) {
        return Vec3d(-p[1] - 0.25 * p[0], p[0] - 0.25 * p[1], 0.5 * p[2]);
    });
    forEachActive(*lic::deriveScalar(*strain, "lambda2"),
                  [](const Coord& ijk, const Vec3d&, double v) { EXPECT_NEAR(v, 1.0, 1e-4) << ijk; });
    forEachActive(*lic::deriveScalar(*vortex, "lambda2"),
                  [](const Coord& ijk, const Vec3d&, double v) { EXPECT_NEAR(v, -15.0 / 16.0, 1e-4) << ijk; });
}

// Voxel size 0.37 and an offset origin: derivatives are in world units. A linear flow has exact
// differences, so every voxel (boundary included) matches the closed form.
TEST(Scalars, WorldUnitsWithVoxelSizeAndOffset)
{
    const Coord res(12, 13, 14);
    const auto vel = lictest::makeField(res, 0.37, Vec3d(-1.3, 2.1, 0.4), linearFlow);
    const Vec3d omega = linearCurl();
    const std::map<std::string, std::function<double(const Vec3d&)>> expected = {
        {"speed", [](const Vec3d& p) { return linearFlow(p).length(); }},
        {"vorticity", [&](const Vec3d&) { return omega.length(); }},
        {"helicity", [&](const Vec3d& p) { return linearFlow(p).dot(omega); }},
        {"streamwise-vorticity",
         [&](const Vec3d& p) { return linearFlow(p).dot(omega) / linearFlow(p).length(); }},
        {"q-criterion", [](const Vec3d&) { return linearQ(); }},
    };
    ASSERT_NE(linearQ(), 0.0);
    for (const auto& [name, f] : expected) {
        const auto s = lic::deriveScalar(*vel, name);
        EXPECT_EQ(s->transform(), vel->transform());
        forEachActive(*s, [&](const Coord& ijk, const Vec3d& p, double value) {
            EXPECT_NEAR(value, f(p), 1e-4 * (1.0 + std::abs(f(p)))) << name << " at " << ijk;
        });
    }
}

// A staggered grid of the same linear flow (component c sampled on the face at ijk − ½e_c):
// averaging faces to centres is exact for a linear flow, so interior voxels match the closed form.
TEST(Scalars, StaggeredGridIsAveragedToCentres)
{
    const Coord res(10);
    const double h = 0.25;
    const auto vel = lictest::makeField(res, h, Vec3d(0.0), [](const Vec3d&) { return Vec3d(0.0); });
    vel->setGridClass(openvdb::GRID_STAGGERED);
    for (auto it = vel->beginValueOn(); it; ++it) {
        Vec3d v;
        for (int c = 0; c < 3; ++c) {
            Vec3d face = vel->transform().indexToWorld(it.getCoord());
            face[c] -= 0.5 * h;
            v[c] = linearFlow(face)[c];
        }
        it.setValue(openvdb::Vec3s(v));
    }
    const auto vort = lic::deriveScalar(*vel, "vorticity");
    const auto q = lic::deriveScalar(*vel, "q-criterion");
    const auto speed = lic::deriveScalar(*vel, "speed");
    forEachActive(*vort, [&](const Coord& ijk, const Vec3d& p, double value) {
        if (!interior(ijk, res)) return;
        EXPECT_NEAR(value, linearCurl().length(), 1e-4) << ijk;
        EXPECT_NEAR(q->tree().getValue(ijk), linearQ(), 1e-4) << ijk;
        EXPECT_NEAR(speed->tree().getValue(ijk), linearFlow(p).length(), 1e-5) << ijk;
    });
}

// The output has the input's active topology, with input active tiles voxelized and holes kept.
TEST(Scalars, TopologyMatchesInputWithoutActiveTiles)
{
    auto vel = lictest::uniformField(20);
    vel->tree().setValueOff(Coord(5, 5, 5));
    vel->tree().setValueOff(Coord(0, 19, 7));
    // An active 8³ tile (level 1) away from the dense block.
    vel->tree().addTile(1, Coord(64, 0, 0), openvdb::Vec3s(1, 0, 0), true);
    ASSERT_EQ(vel->tree().activeTileCount(), 1u);

    openvdb::Vec3STree voxelized(vel->tree());
    voxelized.voxelizeActiveTiles();
    for (const auto& name : lic::derivedScalarNames()) {
        const auto s = lic::deriveScalar(*vel, name);
        EXPECT_TRUE(s->tree().hasSameTopology(voxelized)) << name;
        EXPECT_EQ(s->tree().activeTileCount(), 0u) << name;
        EXPECT_EQ(s->activeVoxelCount(), 20u * 20u * 20u - 2u + 512u) << name;
        EXPECT_FALSE(s->tree().isValueOn(Coord(5, 5, 5))) << name;
        // Inside the tile: the tile's uniform flow (speed 1, no vorticity).
        EXPECT_NEAR(s->tree().getValue(Coord(68, 3, 4)), name == "speed" ? 1.0 : 0.0, 1e-6) << name;
    }
}

TEST(Scalars, UnknownNameThrowsWithTheList)
{
    const auto vel = lictest::uniformField(5);
    try {
        lic::deriveScalar(*vel, "enstrophy");
        FAIL() << "expected lic::InputError";
    } catch (const lic::InputError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("enstrophy"), std::string::npos) << msg;
        for (const auto& name : lic::derivedScalarNames())
            EXPECT_NE(msg.find(name), std::string::npos) << msg;
        EXPECT_NE(msg.find("float grid"), std::string::npos) << msg;
    }
}

TEST(Scalars, ResolveFindsFileGridsAndDerivedNamesWin)
{
    const auto preset = lic::makePresetField("tabbed-jet", Coord(12, 12, 16));
    std::map<std::string, openvdb::FloatGrid::Ptr> file;
    for (const auto& grid : preset.scalars) file[grid->getName()] = grid;
    ASSERT_EQ(file.count("temperature"), 1u);

    // A file grid is returned as is.
    EXPECT_EQ(lic::resolveScalar(*preset.velocity, file, "temperature"), file["temperature"]);

    // A derived name shadows a file grid of the same name.
    file["speed"] = openvdb::FloatGrid::create(-1.0f);
    const auto speed = lic::resolveScalar(*preset.velocity, file, "speed");
    EXPECT_NE(speed, file["speed"]);
    EXPECT_EQ(speed->activeVoxelCount(), preset.velocity->activeVoxelCount());
    const Coord ijk(6, 6, 8);
    EXPECT_NEAR(speed->tree().getValue(ijk), preset.velocity->tree().getValue(ijk).length(), 1e-6);

    // Neither: the message lists both kinds of names.
    try {
        lic::resolveScalar(*preset.velocity, file, "pressure");
        FAIL() << "expected lic::InputError";
    } catch (const lic::InputError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("pressure"), std::string::npos) << msg;
        EXPECT_NE(msg.find("temperature"), std::string::npos) << msg;
        EXPECT_NE(msg.find("q-criterion"), std::string::npos) << msg;
    }
}

// ScalarField::BlockSampler gives ScalarField::at at every output voxel centre, bit for bit:
// per-axis tables where both transforms are axis-aligned (scaled, translated, fields and scalars
// on different lattices, partly negative coordinates, upsampling), ScalarField::at itself where
// they are not (a rotated field).
TEST(Scalars, BlockSamplerMatchesAtBitForBit)
{
    struct Case
    {
        const char* what;
        double fieldVoxel, scalarVoxel;
        Vec3d fieldOrigin, scalarOrigin;
        int upsample;
        bool rotate, separable;
    };
    const Case cases[] = {
        {"unit voxels", 1.0, 1.0, Vec3d(0.0), Vec3d(0.0), 1, false, true},
        {"scaled and offset, upsample 2", 0.37, 0.37, Vec3d(-1.3, 2.1, 0.4), Vec3d(-1.3, 2.1, 0.4), 2, false, true},
        {"scalar on its own lattice, upsample 3", 0.37, 0.53, Vec3d(-1.3, 2.1, 0.4), Vec3d(-2.05, 1.7, -0.33), 3, false,
         true},
        {"rotated field", 0.37, 0.37, Vec3d(-1.3, 2.1, 0.4), Vec3d(-1.3, 2.1, 0.4), 2, true, false},
    };
    for (const Case& c : cases) {
        auto vel = lictest::makeField(Coord(11, 9, 13), c.fieldVoxel, c.fieldOrigin, linearFlow);
        auto scalarSource = lictest::makeField(Coord(13, 12, 10), c.scalarVoxel, c.scalarOrigin, linearFlow);
        if (c.rotate) {
            auto xform = vel->transform().copy();
            xform->postRotate(0.4, openvdb::math::Z_AXIS);
            vel->setTransform(xform);
        }
        const auto scalarGrid = lic::deriveScalar(*scalarSource, "speed");
        const lic::ScalarField scalar(scalarGrid);
        const lic::VelocityField field(vel);
        const lic::OutputDomain domain(field, c.upsample);
        lic::ScalarField::BlockSampler sampler(scalar, domain);
        EXPECT_EQ(sampler.separable(), c.separable) << c.what;
        std::size_t compared = 0, differing = 0;
        for (std::size_t b = 0; b < domain.blockCount(); ++b) {
            const Coord origin = domain.blockOrigin(b);
            sampler.setBlock(origin);
            for (openvdb::Index off = 0; off < openvdb::Index(lic::OutputDomain::kBlockVoxels); ++off) {
                const Coord ijk = origin + Coord(int(off >> 6), int((off >> 3) & 7), int(off & 7));
                const float want = scalar.at(domain.worldOf(ijk)), got = sampler.at(off);
                ++compared;
                if (std::memcmp(&want, &got, sizeof(float)) != 0 && ++differing <= 3)
                    ADD_FAILURE() << c.what << ": at " << ijk << " " << got << " instead of " << want;
            }
        }
        EXPECT_EQ(differing, 0u) << c.what;
        EXPECT_GT(compared, 4000u) << c.what;
    }
}

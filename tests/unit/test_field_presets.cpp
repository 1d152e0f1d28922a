// Unit tests for lic/field/Presets.h: grid conventions and closed-form field values.

#include "lic/util/Error.h"
#include "lic/field/Presets.h"

#include <openvdb/tools/Interpolation.h>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>

namespace {

using openvdb::Coord;
using openvdb::Vec3d;

const std::vector<std::string> kAllNames{"uniform", "rotation", "abc",       "saddle",
                                         "tornado", "vortex-ring", "tabbed-jet"};

std::uint64_t voxelCount(const Coord& res)
{
    return std::uint64_t(res.x()) * std::uint64_t(res.y()) * std::uint64_t(res.z());
}

/// Call fn(ijk, value, worldPosition) for every active voxel of grid.
template<typename GridT, typename Fn>
void forEachVoxel(const GridT& grid, Fn fn)
{
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        ASSERT_TRUE(it.isVoxelValue()) << "active tile at " << it.getCoord();
        fn(it.getCoord(), *it, grid.transform().indexToWorld(it.getCoord()));
    }
}

/// Checks shared by every grid of a preset: full active box of leaf voxels, uniform voxels.
template<typename GridT>
void expectGridConventions(const GridT& grid, const Coord& res, const std::string& context)
{
    SCOPED_TRACE(context);
    EXPECT_EQ(grid.activeVoxelCount(), voxelCount(res));
    EXPECT_EQ(grid.tree().activeTileCount(), 0u);
    EXPECT_EQ(grid.evalActiveVoxelBoundingBox(), openvdb::CoordBBox(Coord(0), res - Coord(1)));
    EXPECT_TRUE(grid.transform().isLinear());
    EXPECT_TRUE(grid.hasUniformVoxels());
    const Vec3d h = grid.voxelSize();
    EXPECT_GT(h.x(), 0.0);
    EXPECT_DOUBLE_EQ(h.x(), h.y());
    EXPECT_DOUBLE_EQ(h.x(), h.z());
    EXPECT_EQ(grid.background(), typename GridT::ValueType(0));
}

/// Numerical in-plane vorticity ∂v/∂x − ∂u/∂y (world units) at world position p.
double curlZ(const openvdb::Vec3SGrid& grid, const Vec3d& p)
{
    const openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> s(grid);
    const double e = grid.voxelSize().x();
    const double dvdx = (s.wsSample(p + Vec3d(e, 0, 0))[1] - s.wsSample(p - Vec3d(e, 0, 0))[1]) / (2 * e);
    const double dudy = (s.wsSample(p + Vec3d(0, e, 0))[0] - s.wsSample(p - Vec3d(0, e, 0))[0]) / (2 * e);
    return dvdx - dudy;
}

template<typename GridT>
void expectIdentical(const GridT& a, const GridT& b)
{
    ASSERT_EQ(a.activeVoxelCount(), b.activeVoxelCount());
    EXPECT_EQ(a.transform(), b.transform());
    auto acc = b.getConstAccessor();
    std::uint64_t mismatches = 0;
    forEachVoxel(a, [&](const Coord& ijk, const auto& value, const Vec3d&) {
        if (!acc.isValueOn(ijk) || acc.getValue(ijk) != value) ++mismatches;
    });
    EXPECT_EQ(mismatches, 0u);
}

// ---- names, descriptions, validation ---------------------------------------------------

TEST(FieldPresets, NamesListsAllSevenInStableOrder)
{
    EXPECT_EQ(lic::presetNames(), kAllNames);
    for (const auto& name : kAllNames) {
        EXPECT_FALSE(lic::presetDescription(name).empty()) << name;
        EXPECT_EQ(lic::presetDescription(name).find('\n'), std::string::npos) << name;
    }
}

TEST(FieldPresets, DefaultResolutions)
{
    EXPECT_EQ(lic::presetDefaultResolution("tabbed-jet"), Coord(101, 101, 148));
    for (const auto& name : kAllNames) {
        if (name != "tabbed-jet") {
            EXPECT_EQ(lic::presetDefaultResolution(name), Coord(64)) << name;
        }
    }
}

TEST(FieldPresets, UnknownNameThrowsListingValidNames)
{
    try {
        lic::makePresetField("hurricane", Coord(8));
        FAIL() << "expected lic::InputError";
    } catch (const lic::InputError& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find("hurricane"), std::string::npos) << message;
        for (const auto& name : kAllNames) EXPECT_NE(message.find(name), std::string::npos) << message;
    }
    EXPECT_THROW(lic::presetDescription("hurricane"), lic::InputError);
    EXPECT_THROW(lic::presetDefaultResolution(""), lic::InputError);
}

TEST(FieldPresets, ResolutionOutOfRangeThrows)
{
    EXPECT_THROW(lic::makePresetField("uniform", Coord(1, 8, 8)), lic::InputError);
    EXPECT_THROW(lic::makePresetField("uniform", Coord(8, 8, 1)), lic::InputError);
    EXPECT_THROW(lic::makePresetField("uniform", Coord(8, 4096, 8)), lic::InputError);
    EXPECT_THROW(lic::makePresetField("uniform", Coord(0, -3, 8)), lic::InputError);
    // Each axis within range but 2^33 voxels in total (checked before allocating anything).
    EXPECT_THROW(lic::makePresetField("uniform", Coord(2048)), lic::InputError);
    try {
        lic::makePresetField("rotation", Coord(8, 4096, 8));
    } catch (const lic::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("4096"), std::string::npos) << e.what();
    }
    EXPECT_NO_THROW(lic::makePresetField("uniform", Coord(2)));
}

// ---- every preset: grid conventions ----------------------------------------------------

class EveryPreset : public ::testing::TestWithParam<std::string>
{
};

TEST_P(EveryPreset, FullBoxOfFiniteLeafVoxels)
{
    const std::string name = GetParam();
    // Odd, unequal resolution: includes voxels on the symmetry axes (ρ = 0, r = 0).
    const Coord res(17, 13, 21);
    const lic::PresetField field = lic::makePresetField(name, res);
    ASSERT_TRUE(field.velocity);
    const openvdb::Vec3SGrid& v = *field.velocity;
    EXPECT_EQ(v.getName(), "velocity");
    EXPECT_EQ(v.getVectorType(), openvdb::VEC_CONTRAVARIANT_RELATIVE);
    EXPECT_TRUE(v.isInWorldSpace());
    EXPECT_EQ(v.getGridClass(), openvdb::GRID_UNKNOWN);
    expectGridConventions(v, res, name + " velocity");

    std::uint64_t nonFinite = 0, nonZero = 0;
    forEachVoxel(v, [&](const Coord&, const openvdb::Vec3s& value, const Vec3d&) {
        if (!std::isfinite(value.x()) || !std::isfinite(value.y()) || !std::isfinite(value.z())) ++nonFinite;
        if (value != openvdb::Vec3s(0.0f)) ++nonZero;
    });
    EXPECT_EQ(nonFinite, 0u) << name;
    EXPECT_GT(nonZero, 0u) << name;

    for (const auto& scalar : field.scalars) {
        ASSERT_TRUE(scalar);
        expectGridConventions(*scalar, res, name + " " + scalar->getName());
        EXPECT_EQ(scalar->transform(), v.transform());
        std::uint64_t bad = 0;
        forEachVoxel(*scalar, [&](const Coord&, float value, const Vec3d&) { bad += !std::isfinite(value); });
        EXPECT_EQ(bad, 0u) << name;
    }
    EXPECT_EQ(field.scalars.size(), name == "tabbed-jet" ? 1u : 0u);
}

INSTANTIATE_TEST_SUITE_P(FieldPresets, EveryPreset, ::testing::ValuesIn(kAllNames),
                         [](const auto& paramInfo) {
                             std::string n = paramInfo.param;
                             std::replace(n.begin(), n.end(), '-', '_');
                             return n;
                         });

// ---- transform placement -----------------------------------------------------------------

TEST(FieldPresets, UniformSpansMinusOneToOne)
{
    const auto field = lic::makePresetField("uniform", Coord(11));
    const auto& xform = field.velocity->transform();
    const Vec3d lo = xform.indexToWorld(Coord(0)), hi = xform.indexToWorld(Coord(10));
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(lo[i], -1.0, 1e-12);
        EXPECT_NEAR(hi[i], 1.0, 1e-12);
    }
    EXPECT_NEAR(field.velocity->voxelSize().x(), 0.2, 1e-12);
    forEachVoxel(*field.velocity, [](const Coord& ijk, const openvdb::Vec3s& value, const Vec3d&) {
        EXPECT_EQ(value, openvdb::Vec3s(1, 0, 0)) << ijk;
    });
}

TEST(FieldPresets, ShorterAxesShareVoxelSizeAndCentre)
{
    // Longest axis y (21 voxels) spans [-1, 1]; x and z use the same h, centred on 0.
    const auto field = lic::makePresetField("saddle", Coord(5, 21, 9));
    const auto& xform = field.velocity->transform();
    EXPECT_NEAR(field.velocity->voxelSize().x(), 0.1, 1e-12);
    const Vec3d lo = xform.indexToWorld(Coord(0)), hi = xform.indexToWorld(Coord(4, 20, 8));
    EXPECT_NEAR(lo.y(), -1.0, 1e-12);
    EXPECT_NEAR(hi.y(), 1.0, 1e-12);
    EXPECT_NEAR(lo.x(), -0.2, 1e-12);
    EXPECT_NEAR(hi.x(), 0.2, 1e-12);
    EXPECT_NEAR(lo.z(), -0.4, 1e-12);
    EXPECT_NEAR(hi.z(), 0.4, 1e-12);
}

TEST(FieldPresets, AbcAndTornadoBoxes)
{
    const auto abc = lic::makePresetField("abc", Coord(16));
    EXPECT_NEAR(abc.velocity->transform().indexToWorld(Coord(0)).x(), 0.0, 1e-12);
    EXPECT_NEAR(abc.velocity->transform().indexToWorld(Coord(15)).z(), 2.0 * std::numbers::pi, 1e-12);
    const auto tornado = lic::makePresetField("tornado", Coord(16));
    EXPECT_NEAR(tornado.velocity->transform().indexToWorld(Coord(0)).y(), 0.0, 1e-12);
    EXPECT_NEAR(tornado.velocity->transform().indexToWorld(Coord(15)).y(), 1.0, 1e-12);
}

TEST(FieldPresets, TabbedJetDefaultBox)
{
    const Coord res = lic::presetDefaultResolution("tabbed-jet");
    const auto field = lic::makePresetField("tabbed-jet", res);
    const auto& xform = field.velocity->transform();
    EXPECT_NEAR(xform.indexToWorld(Coord(0)).z(), 0.0, 1e-12);
    EXPECT_NEAR(xform.indexToWorld(res - Coord(1)).z(), 2.0, 1e-12);
    const Vec3d centre = xform.indexToWorld(Coord(50, 50, 0));
    EXPECT_NEAR(centre.x(), 0.0, 1e-12);
    EXPECT_NEAR(centre.y(), 0.0, 1e-12);
    EXPECT_NEAR(field.velocity->voxelSize().x(), 2.0 / 147.0, 1e-12);
    expectGridConventions(*field.velocity, res, "tabbed-jet default");
}

// ---- closed forms ------------------------------------------------------------------------

TEST(FieldPresets, RotationMatchesSolidBody)
{
    const auto field = lic::makePresetField("rotation", Coord(12, 9, 7));
    forEachVoxel(*field.velocity, [](const Coord& ijk, const openvdb::Vec3s& v, const Vec3d& p) {
        EXPECT_NEAR(v.x(), -p.y(), 1e-5) << ijk;
        EXPECT_NEAR(v.y(), p.x(), 1e-5) << ijk;
        EXPECT_NEAR(v.z(), 0.0, 1e-5) << ijk;
    });
}

TEST(FieldPresets, AbcMatchesFormula)
{
    const double a = std::sqrt(3.0), b = std::sqrt(2.0), c = 1.0;
    const auto field = lic::makePresetField("abc", Coord(10, 14, 12));
    forEachVoxel(*field.velocity, [&](const Coord& ijk, const openvdb::Vec3s& v, const Vec3d& p) {
        const double x = p.x(), y = p.y(), z = p.z();
        EXPECT_NEAR(v.x(), a * std::sin(z) + c * std::cos(y), 1e-5) << ijk;
        EXPECT_NEAR(v.y(), b * std::sin(x) + a * std::cos(z), 1e-5) << ijk;
        EXPECT_NEAR(v.z(), c * std::sin(y) + b * std::cos(x), 1e-5) << ijk;
    });
}

TEST(FieldPresets, SaddleVanishesAtCentreAndMatchesFormula)
{
    const auto field = lic::makePresetField("saddle", Coord(9, 7, 11));
    const openvdb::Vec3s centre = field.velocity->getConstAccessor().getValue(Coord(4, 3, 5));
    EXPECT_NEAR(centre.length(), 0.0, 1e-6);
    forEachVoxel(*field.velocity, [](const Coord& ijk, const openvdb::Vec3s& v, const Vec3d& p) {
        EXPECT_NEAR((Vec3d(v) - Vec3d(p.x(), p.y(), -2.0 * p.z())).length(), 0.0, 1e-5) << ijk;
    });
}

TEST(FieldPresets, VortexRingSwirlsAroundCoreAndDriftsOnAxis)
{
    const auto field = lic::makePresetField("vortex-ring", Coord(41));
    const openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> s(*field.velocity);
    // On the axis (ρ = 0, z = 0) the in-plane velocity vanishes; the ring's induced flow through
    // its middle points +z, with the drift: u_z = Γ/(2πR)(1-e^{-R²/a²}) + 0.1.
    const Vec3d axis = s.wsSample(Vec3d(0.0));
    EXPECT_NEAR(axis.x(), 0.0, 1e-5);
    EXPECT_NEAR(axis.y(), 0.0, 1e-5);
    const double expectedZ = 1.0 / (2 * std::numbers::pi * 0.5) * (1 - std::exp(-0.25 / 0.0225)) + 0.1;
    EXPECT_NEAR(axis.z(), expectedZ, 1e-4);
    // Outside the ring, in its plane, the flow returns along −z.
    EXPECT_LT(s.wsSample(Vec3d(0.75, 0.0, 0.0)).z(), 0.0);
}

// ---- tabbed jet --------------------------------------------------------------------------

TEST(FieldPresets, TabbedJetHasFastCoreCounterRotatingPairsAndHotCore)
{
    const Coord res = lic::presetDefaultResolution("tabbed-jet");
    const auto field = lic::makePresetField("tabbed-jet", res);
    const openvdb::Vec3SGrid& v = *field.velocity;
    auto acc = v.getConstAccessor();
    // Axial velocity on the axis exceeds that near the box edge, at several heights.
    for (int k : {10, 74, 140}) {
        const float onAxis = acc.getValue(Coord(50, 50, k)).z();
        EXPECT_GT(onAxis, acc.getValue(Coord(2, 50, k)).z() + 0.2f) << "z index " << k;
        EXPECT_GT(onAxis, acc.getValue(Coord(2, 2, k)).z() + 0.2f) << "z index " << k;
    }
    // Counter-rotating pairs: at the jet edge R(z) the in-plane curl is positive at
    // θ_k + 0.22 and negative at θ_k − 0.22; between the two the flow is pushed outward.
    const openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> s(v);
    for (double z : {0.5, 1.0, 1.5}) {
        const double radius = 0.3 * (1 + 0.25 * z);
        for (int k = 0; k < 4; ++k) {
            const double base = k * std::numbers::pi / 2;
            auto at = [&](double theta) {
                return Vec3d(radius * std::cos(theta), radius * std::sin(theta), z);
            };
            const double plus = curlZ(v, at(base + 0.22)), minus = curlZ(v, at(base - 0.22));
            EXPECT_GT(plus, 0.5) << "z " << z << " k " << k;
            EXPECT_LT(minus, -0.5) << "z " << z << " k " << k;
            const Vec3d between = s.wsSample(at(base));
            const double radial = between.x() * std::cos(base) + between.y() * std::sin(base);
            EXPECT_GT(radial, 0.05) << "z " << z << " k " << k;
        }
    }
    // Temperature: present, named, hotter on the axis than at the edge, 300 K far away.
    ASSERT_EQ(field.scalars.size(), 1u);
    const openvdb::FloatGrid& t = *field.scalars.front();
    EXPECT_EQ(t.getName(), "temperature");
    expectGridConventions(t, res, "temperature");
    auto tAcc = t.getConstAccessor();
    for (int k : {0, 74, 147}) {
        EXPECT_GT(tAcc.getValue(Coord(50, 50, k)), tAcc.getValue(Coord(0, 50, k)) + 10.0f) << k;
        EXPECT_NEAR(tAcc.getValue(Coord(0, 0, k)), 300.0f, 0.5f) << k;
    }
    EXPECT_NEAR(tAcc.getValue(Coord(50, 50, 0)), 360.0f, 0.5f);
}

// ---- determinism -------------------------------------------------------------------------

TEST(FieldPresets, DeterministicAcrossCallsAndThreadCounts)
{
    for (const std::string name : {"tabbed-jet", "vortex-ring", "tornado"}) {
        SCOPED_TRACE(name);
        const Coord res(23, 19, 31);
        const auto a = lic::makePresetField(name, res);
        const auto b = lic::makePresetField(name, res);
        expectIdentical(*a.velocity, *b.velocity);
        lic::PresetField single;
        {
            tbb::global_control oneThread(tbb::global_control::max_allowed_parallelism, 1);
            single = lic::makePresetField(name, res);
        }
        expectIdentical(*a.velocity, *single.velocity);
        ASSERT_EQ(a.scalars.size(), single.scalars.size());
        for (size_t i = 0; i < a.scalars.size(); ++i) expectIdentical(*a.scalars[i], *single.scalars[i]);
    }
}

} // namespace

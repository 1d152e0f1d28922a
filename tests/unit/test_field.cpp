// VelocityField: sampling, domain, validation.
#include "lic/util/Error.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"

#include "TestFields.h"

#include <openvdb/tools/Interpolation.h>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace lic;
using openvdb::Vec3d;

// The hot loops' integer floor and ceil give std::floor's and std::ceil's integers, float and double,
// on both sides of zero, at integers and half-integers and just either side of them.
TEST(IndexMath, FloorAndCeilMatchTheStandardOnes)
{
    for (int k = -4000; k <= 4000; ++k) {
        const double x = k * 0.125;
        for (const double v : {x, std::nextafter(x, -1e9), std::nextafter(x, 1e9)}) {
            ASSERT_EQ(lic::detail::floorIndex(v), int(std::floor(v))) << v;
            ASSERT_EQ(lic::detail::ceilIndex(v), int(std::ceil(v))) << v;
            const float f = float(v);
            ASSERT_EQ(lic::detail::floorIndex(f), int(std::floor(f))) << f;
            ASSERT_EQ(lic::detail::ceilIndex(f), int(std::ceil(f))) << f;
        }
    }
    for (int a = -20; a <= 20; ++a) ASSERT_EQ(lic::detail::floorDiv(a, 8), int(std::floor(a / 8.0))) << a;
}

TEST(Field, LinearFieldIsSampledExactly)
{
    VelocityField field(lictest::rotationField(21));
    for (const Vec3d p : {Vec3d(0.123, -0.456, 0.3), Vec3d(-0.91, 0.77, -0.5), Vec3d(0.0)}) {
        Vec3d v;
        ASSERT_TRUE(field.sample(p, v));
        EXPECT_NEAR(v[0], -p[1], 1e-6);
        EXPECT_NEAR(v[1], p[0], 1e-6);
        EXPECT_NEAR(v[2], 0.0, 1e-6);
    }
}

TEST(Field, MatchesOpenVdbBoxSamplerInside)
{
    auto grid = lictest::abcField(16);
    VelocityField field(grid);
    openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> ref(*grid);
    for (int i = 0; i < 50; ++i) {
        const Vec3d p(0.3 + 0.11 * i, 5.9 - 0.1 * i, 1.0 + 0.07 * i);
        Vec3d v;
        ASSERT_TRUE(field.sample(p, v));
        const openvdb::Vec3s r = ref.wsSample(p);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], r[c], 1e-5) << p;
    }
}

TEST(Field, StaggeredMatchesOpenVdbStaggeredSampler)
{
    auto grid = lictest::abcField(16);
    grid->setGridClass(openvdb::GRID_STAGGERED);
    VelocityField field(grid);
    ASSERT_TRUE(field.isStaggered());
    openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::StaggeredBoxSampler> ref(*grid);
    for (int i = 0; i < 50; ++i) {
        const Vec3d p(0.5 + 0.1 * i, 5.5 - 0.09 * i, 1.0 + 0.08 * i);
        Vec3d v;
        ASSERT_TRUE(field.sample(p, v));
        const openvdb::Vec3s r = ref.wsSample(p);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], r[c], 1e-5) << p;
    }
}

TEST(Field, DomainIsTheActiveVoxelsExtent)
{
    VelocityField field(lictest::uniformField(21)); // centres span [−1, 1], h = 0.1
    const openvdb::BBoxd b = field.worldBBox();
    for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(b.min()[a], -1.05, 1e-9);
        EXPECT_NEAR(b.max()[a], 1.05, 1e-9);
    }
    Vec3d v;
    EXPECT_TRUE(field.sample(Vec3d(1.04, 0, 0), v));
    EXPECT_NEAR(v[0], 1.0, 1e-6); // outer half voxel: nearest centre's value
    EXPECT_FALSE(field.sample(Vec3d(1.06, 0, 0), v));
    EXPECT_FALSE(field.contains(Vec3d(0, 0, -1.2)));
}

TEST(Field, GradientOfRotation)
{
    VelocityField field(lictest::rotationField(21));
    Vec3d v;
    openvdb::Mat3d dv;
    ASSERT_TRUE(field.sampleGradient(Vec3d(0.2, 0.3, 0.1), v, dv));
    // v = (−y, x, 0): ∂v_x/∂y = −1, ∂v_y/∂x = 1, the rest 0. Vorticity 2Ω = 2.
    EXPECT_NEAR(dv[0][1], -1.0, 1e-6);
    EXPECT_NEAR(dv[1][0], 1.0, 1e-6);
    EXPECT_NEAR(dv[0][0], 0.0, 1e-6);
    EXPECT_NEAR(dv[2][2], 0.0, 1e-6);
    EXPECT_NEAR(dv[1][0] - dv[0][1], 2.0, 1e-6);
}

TEST(Field, RefusesBadFields)
{
    auto nan = lictest::uniformField(9);
    nan->tree().setValue(openvdb::Coord(3, 4, 5), openvdb::Vec3s(std::numeric_limits<float>::quiet_NaN(), 0, 0));
    try {
        VelocityField f(nan);
        FAIL() << "NaN accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("NaN"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("[3, 4, 5]"), std::string::npos) << e.what();
    }
    auto zero = lictest::makeField(openvdb::Coord(5), 1.0, Vec3d(0.0), [](const Vec3d&) { return Vec3d(0.0); });
    EXPECT_THROW(VelocityField{zero}, InputError);
    EXPECT_THROW(VelocityField{openvdb::Vec3SGrid::create()}, InputError);
}

TEST(OutputDomain, RefinesTheFieldHalfVoxelAligned)
{
    VelocityField field(lictest::uniformField(11)); // centres at −1 … 1, h = 0.2
    OutputDomain d(field, 2);
    EXPECT_EQ(d.indexBBox(), openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(21)));
    EXPECT_EQ(d.activeVoxelCount(), 22u * 22u * 22u);
    EXPECT_NEAR(d.voxelSize(), 0.1, 1e-12);
    // Output voxel 0 is the lower half of field voxel 0 (centre −1, extent [−1.1, −0.9]).
    EXPECT_NEAR(d.worldOf(openvdb::Coord(0))[0], -1.05, 1e-12);
    EXPECT_NEAR(d.worldOf(openvdb::Coord(21))[0], 1.05, 1e-12);
    // Slots round-trip.
    for (const openvdb::Coord ijk : {openvdb::Coord(0), openvdb::Coord(7, 8, 9), openvdb::Coord(21, 0, 13)}) {
        const std::int64_t s = d.slotOf(ijk);
        ASSERT_GE(s, 0);
        EXPECT_EQ(d.coordOf(std::size_t(s)), ijk);
    }
    EXPECT_EQ(d.slotOf(openvdb::Coord(22, 0, 0)), -1);
    EXPECT_THROW(OutputDomain(field, 0), InputError);
    EXPECT_THROW(OutputDomain(field, 17), InputError);
}

TEST(OutputDomain, InactiveFieldVoxelsStayInactive)
{
    auto grid = lictest::uniformField(8);
    grid->tree().setValueOff(openvdb::Coord(2, 2, 2));
    VelocityField field(grid);
    OutputDomain d(field, 3);
    EXPECT_EQ(d.activeVoxelCount(), (8u * 8u * 8u - 1u) * 27u);
    EXPECT_EQ(d.slotOf(openvdb::Coord(7, 8, 6)), -1);  // inside field voxel (2,2,2)
    EXPECT_GE(d.slotOf(openvdb::Coord(9, 8, 6)), 0);   // field voxel (3,2,2)
    std::vector<float> ones(d.slotCount(), 1.0f);
    auto g = d.makeGrid(ones, "density");
    EXPECT_EQ(g->activeVoxelCount(), d.activeVoxelCount());
    EXPECT_EQ(g->tree().activeTileCount(), 0u);
    EXPECT_EQ(g->getGridClass(), openvdb::GRID_FOG_VOLUME);
}

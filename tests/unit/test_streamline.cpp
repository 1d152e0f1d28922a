// Streamline integration against closed forms.
#include "lic/util/Error.h"
#include "lic/engine/Streamline.h"

#include "TestFields.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace lic;
using openvdb::Vec3d;

namespace {
TraceSettings settings(double step, int maxSamples, Integrator integ)
{
    TraceSettings s;
    s.step = step;
    s.maxSamples = maxSamples;
    s.integrator = integ;
    s.tolerance = 1e-7;
    s.maxStep = 0.05;
    return s;
}
} // namespace

class BothIntegrators : public ::testing::TestWithParam<Integrator> {};

TEST_P(BothIntegrators, UniformFlowIsAStraightLineOfExactLength)
{
    VelocityField field(lictest::uniformField(21, {0.3, 0.0, 0.0})); // speed does not matter
    std::vector<Vec3d> pts;
    const StopReason why = traceStreamline(field, Vec3d(-0.5, 0.1, -0.2), +1.0, settings(0.01, 50, GetParam()), pts);
    EXPECT_EQ(why, StopReason::Length);
    ASSERT_EQ(pts.size(), 50u);
    for (std::size_t i = 0; i < pts.size(); ++i) {
        EXPECT_NEAR(pts[i][0], -0.5 + 0.01 * double(i + 1), 1e-9) << "sample " << i;
        EXPECT_NEAR(pts[i][1], 0.1, 1e-12);
        EXPECT_NEAR(pts[i][2], -0.2, 1e-12);
    }
}

TEST_P(BothIntegrators, UpstreamGoesBackwards)
{
    VelocityField field(lictest::uniformField(21));
    std::vector<Vec3d> pts;
    traceStreamline(field, Vec3d(0.0), -1.0, settings(0.02, 10, GetParam()), pts);
    ASSERT_EQ(pts.size(), 10u);
    EXPECT_NEAR(pts.back()[0], -0.2, 1e-9);
}

TEST_P(BothIntegrators, StopsAtTheDomainBoundary)
{
    // Domain: voxel centres span [−1, 1], so the domain (voxel extents) ends at x = 1 + h/2.
    VelocityField field(lictest::uniformField(21));
    const double h = 0.1;
    std::vector<Vec3d> pts;
    const StopReason why = traceStreamline(field, Vec3d(0.5, 0, 0), +1.0, settings(0.01, 1000, GetParam()), pts);
    EXPECT_EQ(why, StopReason::Boundary);
    ASSERT_FALSE(pts.empty());
    EXPECT_LE(pts.back()[0], 1.0 + h / 2 + 1e-9);
    EXPECT_GT(pts.back()[0], 1.0 + h / 2 - 0.011);
    for (const Vec3d& p : pts) EXPECT_TRUE(field.contains(p));
}

TEST_P(BothIntegrators, StopsAtZeroVelocity)
{
    // v = (−x, 0, 0): flow converges on the plane x = 0, where it is zero.
    auto grid = lictest::makeField(openvdb::Coord(21), 0.1, Vec3d(-1.0),
                                   [](const Vec3d& p) { return Vec3d(-p[0], 0, 0); });
    VelocityField field(grid);
    TraceSettings s = settings(0.01, 100000, GetParam());
    s.minSpeed = 1e-3;
    std::vector<Vec3d> pts;
    const StopReason why = traceStreamline(field, Vec3d(0.5, 0, 0), +1.0, s, pts);
    EXPECT_EQ(why, StopReason::ZeroVelocity);
    ASSERT_FALSE(pts.empty());
    EXPECT_LT(std::abs(pts.back()[0]), 0.02);
    EXPECT_LT(pts.size(), 100u); // it cannot go past the critical point
}

TEST_P(BothIntegrators, CallerCanStop)
{
    VelocityField field(lictest::uniformField(21));
    std::vector<Vec3d> pts;
    int calls = 0;
    const StopReason why = traceStreamline(field, Vec3d(0.0), +1.0, settings(0.01, 100, GetParam()), pts,
                                           [&](const Vec3d&) { return ++calls < 7; });
    EXPECT_EQ(why, StopReason::Caller);
    EXPECT_EQ(pts.size(), 7u);
}

INSTANTIATE_TEST_SUITE_P(Streamline, BothIntegrators, ::testing::Values(Integrator::RK4, Integrator::RK45),
                         [](const auto& p) { return std::string(toString(p.param)); });

TEST(Streamline, RotationCircleClosesWithRK45)
{
    // Solid-body rotation is linear, so trilinear sampling is exact: streamlines are circles.
    VelocityField field(lictest::rotationField(41));
    const double r = 0.6, step = 0.01;
    const int perTurn = int(std::lround(2 * M_PI * r / step));
    TraceSettings s = settings(step, perTurn, Integrator::RK45);
    s.tolerance = 1e-6;
    s.maxStep = 0.1;
    std::vector<Vec3d> pts;
    EXPECT_EQ(traceStreamline(field, Vec3d(r, 0, 0.2), +1.0, s, pts), StopReason::Length);
    double maxDev = 0;
    for (const Vec3d& p : pts) {
        maxDev = std::max(maxDev, std::abs(std::hypot(p[0], p[1]) - r));
        EXPECT_NEAR(p[2], 0.2, 1e-9);
    }
    EXPECT_LT(maxDev / r, 1e-4) << "radius not conserved";
    // After one turn (arc length 2πr) it is back at the start, to the arc-length rounding.
    const double arc = perTurn * step, angle = arc / r;
    EXPECT_NEAR(pts.back()[0], r * std::cos(angle), 1e-4);
    EXPECT_NEAR(pts.back()[1], r * std::sin(angle), 1e-4);
    // Counter-clockwise about +z.
    EXPECT_GT(pts[10][1], 0.0);
}

TEST(Streamline, RotationWithRK4StaysOnTheCircle)
{
    VelocityField field(lictest::rotationField(41));
    const double r = 0.5, step = 0.01;
    std::vector<Vec3d> pts;
    traceStreamline(field, Vec3d(0, r, 0), +1.0, settings(step, int(2 * M_PI * r / step), Integrator::RK4), pts);
    double maxDev = 0;
    for (const Vec3d& p : pts) maxDev = std::max(maxDev, std::abs(std::hypot(p[0], p[1]) - r));
    EXPECT_LT(maxDev / r, 1e-6);
}

TEST(Streamline, RK45SamplesAtUniformArcLength)
{
    // RK45 takes steps up to 10× the sample spacing; the Hermite placement must still put the
    // samples 0.02 apart along the curve, on the circle.
    VelocityField field(lictest::rotationField(41));
    TraceSettings s = settings(0.02, 100, Integrator::RK45);
    s.tolerance = 1e-5;
    s.maxStep = 0.2;
    std::vector<Vec3d> pts;
    traceStreamline(field, Vec3d(0.4, 0, 0), +1.0, s, pts);
    ASSERT_EQ(pts.size(), 100u);
    for (std::size_t i = 1; i < pts.size(); ++i) {
        EXPECT_NEAR((pts[i] - pts[i - 1]).length(), 0.02, 2e-4) << "uniform arc length at " << i;
        EXPECT_NEAR(std::hypot(pts[i][0], pts[i][1]), 0.4, 1e-3);
    }
}

TEST(Streamline, IntegratorNames)
{
    EXPECT_EQ(integratorFromString("rk4"), Integrator::RK4);
    EXPECT_EQ(integratorFromString("rk45"), Integrator::RK45);
    EXPECT_THROW(integratorFromString("euler"), InputError);
}

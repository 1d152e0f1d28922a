// Spot input textures: distributions and their evenness, the smooth sphere profile, the analytic
// multi-channel texture, the single-spot peak, halos enclosing lines, width levels, ridges.
#include "lic/engine/Engine.h"
#include "lic/engine/Gather.h"
#include "lic/texture/Noise.h"
#include "lic/field/Region.h"
#include "lic/texture/Spots.h"

#include "TestFields.h"

#include <gtest/gtest.h>

#include <cstdio>

using openvdb::Vec3d;

namespace {

const openvdb::BBoxd kBox(Vec3d(0.0), Vec3d(96.0));
constexpr double kSpacing = 6.0;

std::vector<Vec3d> place(lic::SpotDistribution d, double jitter = 0.25, std::uint64_t seed = 7)
{
    return lic::placeSpots({d, kSpacing, jitter, seed}, kBox);
}

lic::SpotStats stats(const std::vector<Vec3d>& s) { return lic::spotStatistics(s, kBox, kSpacing, 3, 1500); }

} // namespace

TEST(Spots, DistributionNamesRoundTrip)
{
    for (auto d : {lic::SpotDistribution::Regular, lic::SpotDistribution::Random, lic::SpotDistribution::Jittered,
                   lic::SpotDistribution::Poisson})
        EXPECT_EQ(lic::spotDistributionFromString(lic::toString(d)), d);
    EXPECT_THROW(lic::spotDistributionFromString("gaussian"), lic::InputError);
}

TEST(Spots, AllDistributionsAreDeterministicInsideTheBoxAndAboutOnePerCell)
{
    const double lattice = std::pow(96.0 / kSpacing, 3); // 4096
    for (auto d : {lic::SpotDistribution::Regular, lic::SpotDistribution::Random, lic::SpotDistribution::Jittered,
                   lic::SpotDistribution::Poisson}) {
        SCOPED_TRACE(lic::toString(d));
        const auto a = place(d), b = place(d);
        ASSERT_EQ(a, b);
        for (const auto& p : a) ASSERT_TRUE(kBox.isInside(p));
        EXPECT_NEAR(double(a.size()) / lattice, 1.0, 0.12);
        if (d != lic::SpotDistribution::Regular) {
            EXPECT_NE(place(d, 0.25, 8), a) << "seed must matter";
        }
    }
    EXPECT_EQ(place(lic::SpotDistribution::Regular).size(), 4096u);
    EXPECT_EQ(place(lic::SpotDistribution::Random).size(), 4096u);
}

TEST(Spots, PoissonDiskKeepsItsMinimumDistanceAndIsMoreEvenThanRandom)
{
    const auto regular = stats(place(lic::SpotDistribution::Regular));
    const auto random = stats(place(lic::SpotDistribution::Random));
    const auto jittered = stats(place(lic::SpotDistribution::Jittered, 0.25));
    const auto jitteredFull = stats(place(lic::SpotDistribution::Jittered, 1.0));
    const auto poisson = stats(place(lic::SpotDistribution::Poisson));
    std::printf("distribution    count  min-dist/d  mean-nn/d  plane-CoV  axis-CoV  empty-axis\n");
    auto row = [](const char* name, const lic::SpotStats& s) {
        std::printf("%-14s %6zu  %9.3f  %9.3f  %9.3f  %8.3f  %9.3f\n", name, s.count, s.minDistance / kSpacing,
                    s.meanNearest / kSpacing, s.planeCov, s.axisPlaneCov, s.emptyAxisFraction);
    };
    row("regular", regular);
    row("random", random);
    row("jittered 0.25", jittered);
    row("jittered 1.0", jitteredFull);
    row("poisson", poisson);

    EXPECT_NEAR(regular.minDistance, kSpacing, 1e-9);
    EXPECT_GE(poisson.minDistance, 0.7 * kSpacing);
    EXPECT_GE(poisson.minDistance, lic::kPoissonRadius * kSpacing - 1e-9);
    EXPECT_LT(random.minDistance, 0.3 * kSpacing); // clumps
    // The seed's claim: about equally many spots on any plane.
    EXPECT_LT(poisson.planeCov, random.planeCov);
    EXPECT_LT(poisson.planeCov, 0.8 * random.planeCov);
    // A lattice (or small jitter) leaves whole rows empty; Poisson-disk does not.
    EXPECT_GT(regular.emptyAxisFraction, 0.3);
    EXPECT_GT(jittered.emptyAxisFraction, 0.1);
    EXPECT_LT(poisson.emptyAxisFraction, 0.01);
    EXPECT_LT(poisson.axisPlaneCov, jittered.axisPlaneCov);
}

TEST(Spots, AbsurdSpacingIsRefusedBeforeAllocating)
{
    EXPECT_THROW(lic::placeSpots({lic::SpotDistribution::Random, 0.001, 0.2, 1}, kBox), lic::InputError);
    EXPECT_THROW(lic::placeSpots({lic::SpotDistribution::Poisson, 0.001, 0.2, 1}, kBox), lic::InputError);
    EXPECT_THROW(lic::placeSpots({lic::SpotDistribution::Regular, 0.0, 0.2, 1}, kBox), lic::InputError);
}

TEST(Spots, SelectEvenlyKeepsTheDistanceAndCoversTheCandidates)
{
    std::vector<Vec3d> plane; // dense candidates on z = 10
    for (int i = 0; i < 200; ++i)
        for (int j = 0; j < 200; ++j) plane.emplace_back(i * 0.25, j * 0.25, 10.0);
    const auto chosen = lic::selectEvenly(plane, 4.0, 1);
    ASSERT_EQ(chosen, lic::selectEvenly(plane, 4.0, 1));
    for (std::size_t a = 0; a < chosen.size(); ++a)
        for (std::size_t b = a + 1; b < chosen.size(); ++b) ASSERT_GE((chosen[a] - chosen[b]).length(), 4.0);
    // Maximal: every candidate is within the distance of a chosen one.
    for (std::size_t c = 0; c < plane.size(); c += 97) {
        double best = 1e9;
        for (const auto& s : chosen) best = std::min(best, (s - plane[c]).length());
        ASSERT_LT(best, 4.0);
    }
}

TEST(Spots, ProfileIsASmoothEdgedSphere)
{
    double slope = 0;
    EXPECT_EQ(lic::spotProfile(0.0, 2.0, slope), 1.0);
    EXPECT_EQ(lic::spotProfile(1.5, 2.0, slope), 1.0);
    EXPECT_NEAR(lic::spotProfile(2.0, 2.0, slope), 0.5, 1e-12);
    EXPECT_EQ(lic::spotProfile(2.5, 2.0, slope), 0.0);
    double prev = 1.0;
    for (double d = 0; d < 3; d += 0.01) {
        double s;
        const double f = lic::spotProfile(d, 2.0, s);
        ASSERT_LE(f, prev + 1e-15);
        prev = f;
        double s1, s2;
        const double fd = (lic::spotProfile(d + 1e-6, 2.0, s1) - lic::spotProfile(d - 1e-6, 2.0, s2)) / 2e-6;
        ASSERT_NEAR(s, fd, 1e-4) << d;
    }
    // A radius below one voxel still peaks at 1 with a narrower edge.
    EXPECT_EQ(lic::spotProfile(0.0, 0.4, slope), 1.0);
    EXPECT_EQ(lic::spotProfile(0.61, 0.4, slope), 0.0);
}

TEST(Spots, TextureMatchesBruteForceHasExactGradientsAndHalosEncloseLines)
{
    lic::SpotSet set;
    set.centers = lic::placeSpots({lic::SpotDistribution::Random, 3.0, 0, 5}, openvdb::BBoxd(Vec3d(0), Vec3d(24)));
    set.weights.assign(set.centers.size(), 1.0f);
    set.weights[3] = 0.5f;
    const std::array<double, 2> radii{1.0, 1.8};
    const lic::SpotTexture<2> tex(set, radii, 2.0);
    ASSERT_EQ(lic::SpotTexture<2>::kChannels, 4);
    std::uint64_t h = 1;
    for (int t = 0; t < 400; ++t) {
        h = lic::hashCoord(h, t, 0, 0);
        const Vec3d p(double(h % 2400) / 100.0, double((h >> 16) % 2400) / 100.0, double((h >> 32) % 2400) / 100.0);
        float v[4], g[12];
        tex.sampleGradient(p, v, g);
        for (int c = 0; c < 4; ++c) {
            const double r = c < 2 ? radii[std::size_t(c)] : 2.0 * radii[std::size_t(c - 2)];
            double ref = 0, slope;
            for (std::size_t s = 0; s < set.centers.size(); ++s)
                ref += set.weights[s] * lic::spotProfile((p - set.centers[s]).length(), r, slope);
            ASSERT_NEAR(v[c], ref, 1e-5) << "channel " << c;
        }
        EXPECT_GE(v[2], v[0] - 1e-6);
        EXPECT_GE(v[3], v[1] - 1e-6);
        for (int a = 0; a < 3; ++a) {
            Vec3d e(0.0);
            e[a] = 1e-4;
            float vp[4], vm[4];
            tex.sample(p + e, vp);
            tex.sample(p - e, vm);
            for (int c = 0; c < 4; ++c) ASSERT_NEAR(g[3 * c + a], (vp[c] - vm[c]) / 2e-4, 2e-2);
        }
    }
}

TEST(Spots, PeakIsTheValueOfALineThroughOneSpot)
{
    // One spot in uniform flow along x: voxels on the line through its centre, within the kernel
    // half-length of it, have the peak value; voxels off the line have less.
    auto grid = lictest::uniformField(17);
    const lic::VelocityField field(grid);
    const lic::OutputDomain domain(field, 2); // 34³
    lic::SpotSet set;
    const Vec3d centre(16.0, 16.0, 16.0); // a voxel centre
    set.centers = {centre};
    set.weights = {1.0f};
    lic::LicSettings s;
    s.engine = lic::EngineType::Naive;
    s.length = 8;
    s.step = 0.5;
    const lic::LicResult r = lic::convolveSpots(field, domain, set, {1.5}, 2.0, s);
    ASSERT_EQ(r.channels.size(), 2u);
    const double peak = lic::spotPeak(s, 1.5), haloPeak = lic::spotPeak(s, 3.0);
    EXPECT_NEAR(peak, 2.0 * 1.5 / 0.5 / 33.0, 0.02); // ≈ (2r/h)/(2n+1)
    for (int dx = -4; dx <= 4; ++dx) {
        const auto slot = domain.slotOf(openvdb::Coord(16 + dx, 16, 16));
        ASSERT_GE(slot, 0);
        EXPECT_NEAR(r.channels[0][std::size_t(slot)] / peak, 1.0, 0.03) << dx;
        EXPECT_NEAR(r.channels[1][std::size_t(slot)] / haloPeak, 1.0, 0.03) << dx;
    }
    // Two voxels off the line: beyond the line's radius (1.5 + ½ edge), inside the halo's (3),
    // whose chord there is √(3² − 2²)/3 = 0.75 of its diameter.
    const auto off = std::size_t(domain.slotOf(openvdb::Coord(16, 18, 16)));
    EXPECT_LT(r.channels[0][off], 0.05 * peak);
    EXPECT_NEAR(r.channels[1][off] / haloPeak, 0.75, 0.1);
    const auto far = std::size_t(domain.slotOf(openvdb::Coord(16 + 12, 16, 16)));
    EXPECT_EQ(r.channels[0][far], 0.0f);              // past the kernel's reach
}

namespace {

/// Fraction of active voxels above 0.05 per channel after peak normalisation.
std::vector<double> litFractions(const lic::LicResult& r, const lic::OutputDomain& domain, const lic::LicSettings& s,
                                 const std::vector<double>& radii, double haloScale)
{
    const std::size_t K = radii.size();
    std::vector<double> out;
    for (std::size_t c = 0; c < 2 * K; ++c) {
        const double peak = lic::spotPeak(s, c < K ? radii[c] : radii[c - K] * haloScale);
        std::size_t lit = 0;
        for (std::size_t slot = 0; slot < r.channels[c].size(); ++slot)
            if (domain.isActive(slot) && r.channels[c][slot] / peak > 0.05) ++lit;
        out.push_back(double(lit) / double(domain.activeVoxelCount()));
    }
    return out;
}

} // namespace

TEST(Spots, WiderLevelsLightMoreVoxelsAndHalosEncloseLinesAlongCurvedStreamlines)
{
    auto grid = lictest::abcField(24);
    const lic::VelocityField field(grid);
    const lic::OutputDomain domain(field, 2);
    lic::SpotSet set;
    const openvdb::CoordBBox ib = domain.indexBBox();
    set.centers = lic::placeSpots({lic::SpotDistribution::Poisson, 8.0, 0, 3},
                                  openvdb::BBoxd(ib.min().asVec3d(), ib.max().asVec3d()));
    set.weights.assign(set.centers.size(), 1.0f);
    const std::vector<double> radii{0.75, 1.25, 2.0};
    lic::LicSettings s;
    s.engine = lic::EngineType::Naive;
    s.length = 10;
    const lic::LicResult r = lic::convolveSpots(field, domain, set, radii, 2.0, s);
    ASSERT_EQ(r.channels.size(), 6u);
    // Naive LIC is a positive weighted sum of texture values and halo ≥ line pointwise.
    for (std::size_t k = 0; k < 3; ++k)
        for (std::size_t slot = 0; slot < r.channels[k].size(); ++slot)
            ASSERT_GE(r.channels[3 + k][slot], r.channels[k][slot] - 1e-6f);
    const auto lit = litFractions(r, domain, s, radii, 2.0);
    std::printf("lit fraction per level: line %.4f %.4f %.4f  halo %.4f %.4f %.4f (%zu spots)\n", lit[0], lit[1],
                lit[2], lit[3], lit[4], lit[5], set.centers.size());
    EXPECT_LT(lit[0], lit[1]);
    EXPECT_LT(lit[1], lit[2]);
    EXPECT_LT(lit[3], lit[4]);
    EXPECT_LT(lit[4], lit[5]);
    for (std::size_t k = 0; k < 3; ++k) EXPECT_GT(lit[3 + k], 1.5 * lit[k]);
}

TEST(Spots, FastEngineAgreesWithNaiveOnSpots)
{
    auto grid = lictest::abcField(20);
    const lic::VelocityField field(grid);
    const lic::OutputDomain domain(field, 2);
    const openvdb::CoordBBox ib = domain.indexBBox();
    lic::SpotSet set;
    set.centers = lic::placeSpots({lic::SpotDistribution::Jittered, 6.0, 0.8, 2},
                                  openvdb::BBoxd(ib.min().asVec3d(), ib.max().asVec3d()));
    set.weights.assign(set.centers.size(), 1.0f);
    lic::LicSettings s;
    s.length = 10;
    s.engine = lic::EngineType::Naive;
    const auto naive = lic::convolveSpots(field, domain, set, {1.5}, 2.0, s);
    s.engine = lic::EngineType::Fast;
    const auto fast = lic::convolveSpots(field, domain, set, {1.5}, 2.0, s);
    for (std::size_t c = 0; c < 2; ++c) {
        double sxy = 0, sx = 0, sy = 0, sxx = 0, syy = 0, n = 0;
        for (std::size_t slot = 0; slot < naive.channels[c].size(); ++slot) {
            if (!domain.isActive(slot)) continue;
            const double x = naive.channels[c][slot], y = fast.channels[c][slot];
            sx += x, sy += y, sxx += x * x, syy += y * y, sxy += x * y, n += 1;
        }
        const double corr = (sxy - sx * sy / n) / std::sqrt((sxx - sx * sx / n) * (syy - sy * sy / n));
        std::printf("spots fast vs naive, channel %zu: correlation %.4f\n", c, corr);
        EXPECT_GT(corr, 0.95);
    }
}

TEST(Region, RoiWeightIsOneInsideAndFallsSmoothlyToZero)
{
    EXPECT_EQ(lic::roiWeight(0.5, 0.0, 1.0), 1.0f);
    EXPECT_EQ(lic::roiWeight(0.0, 0.0, 1.0), 1.0f);
    EXPECT_EQ(lic::roiWeight(1.0, 0.0, 1.0), 1.0f);
    EXPECT_NEAR(lic::roiWeight(1.025, 0.0, 1.0), 0.5f, 1e-6);
    EXPECT_EQ(lic::roiWeight(1.06, 0.0, 1.0), 0.0f);
    EXPECT_EQ(lic::roiWeight(-0.06, 0.0, 1.0), 0.0f);
    EXPECT_EQ(lic::roiWeight(std::nan(""), 0.0, 1.0), 0.0f);
}

TEST(Region, RidgePointsLieOnTheRidgeOfAGaussianSlab)
{
    // s = exp(−((z − 10.3)/3)²) on a 24×24×24 grid: the ridge is the plane z = 10.3 (index units).
    auto g = openvdb::FloatGrid::create(0.0f);
    auto acc = g->getAccessor();
    for (int i = 0; i < 24; ++i)
        for (int j = 0; j < 24; ++j)
            for (int k = 0; k < 24; ++k)
                acc.setValueOn(openvdb::Coord(i, j, k), float(std::exp(-std::pow((k - 10.3) / 3.0, 2))));
    const auto pts = lic::ridgePoints(*g, 0.5);
    ASSERT_EQ(pts.size(), 22u * 22u); // one layer of interior voxels
    for (const auto& p : pts) ASSERT_NEAR(p[2], 10.3, 0.05);
    EXPECT_TRUE(lic::ridgePoints(*g, 1.5).empty());
    // |∇s| of a linear ramp is its slope.
    auto ramp = openvdb::FloatGrid::create(0.0f);
    ramp->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    auto ra = ramp->getAccessor();
    for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j)
            for (int k = 0; k < 8; ++k) ra.setValueOn(openvdb::Coord(i, j, k), float(3 * i));
    const auto mag = lic::gradientMagnitude(*ramp, "ramp-gradient");
    EXPECT_NEAR(mag->tree().getValue(openvdb::Coord(4, 4, 4)), 6.0f, 1e-4);
}

// The splat engine: agreement with the naive gather on the same spots (all channels, box and exp
// kernels, straight and diverging flows, walls), bit-identical for any thread count, work that
// follows the lines and not the box, and one trace for a loop.
#include "lic/composite/Animation.h"
#include "lic/engine/Engine.h"
#include "lic/engine/Gather.h"
#include "lic/field/Presets.h"
#include "lic/texture/Noise.h"
#include "lic/engine/Splat.h"
#include "lic/texture/Spots.h"

#include "TestFields.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>

using namespace lic;

namespace {

SpotSet poissonSpots(const OutputDomain& domain, double spacing, std::uint64_t seed)
{
    const openvdb::CoordBBox ib = domain.indexBBox();
    SpotSet set;
    set.centers = placeSpots({SpotDistribution::Poisson, spacing, 0.25, seed},
                             openvdb::BBoxd(ib.min().asVec3d(), ib.max().asVec3d()));
    set.weights.assign(set.centers.size(), 1.0f);
    return set;
}

/// The small tabbed jet (24 × 24 × 36, upsample 2), Poisson spots `spacing` apart and splat
/// settings of length 8.
struct SmallJetSpots
{
    VelocityField field{makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36)).velocity};
    OutputDomain domain{field, 2};
    SpotSet set;
    LicSettings settings;
    SmallJetSpots(double spacing, std::uint64_t seed)
        : set(poissonSpots(domain, spacing, seed))
    {
        settings.engine = EngineType::Splat;
        settings.length = 8;
    }
};

/// Pearson correlation over active voxels where either value exceeds 0.001.
double correlation(const OutputDomain& d, const std::vector<float>& a, const std::vector<float>& b)
{
    double sxy = 0, sx = 0, sy = 0, sxx = 0, syy = 0, n = 0;
    for (std::size_t s = 0; s < a.size(); ++s) {
        if (!d.isActive(s) || (a[s] <= 0.001f && b[s] <= 0.001f)) continue;
        sx += a[s], sy += b[s], sxx += double(a[s]) * a[s], syy += double(b[s]) * b[s], sxy += double(a[s]) * b[s], n += 1;
    }
    return (sxy - sx * sy / n) / std::sqrt((sxx - sx * sx / n) * (syy - sy * sy / n));
}

/// Mean |a − b| over the active voxels.
double meanAbsDiff(const OutputDomain& d, const std::vector<float>& a, const std::vector<float>& b)
{
    double s = 0, n = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        if (d.isActive(i)) s += std::abs(double(a[i]) - double(b[i])), n += 1;
    return s / n;
}

} // namespace

TEST(SplatTables, MatchTheWindowSumOfAStraightLine)
{
    // W(τ, d) is the window average of the spot profile along a straight line at distance d, the
    // window centred τ from the spot: compare with the sum worked out directly.
    LicSettings s;
    s.length = 6;
    s.step = 0.5;
    const SplatTables t({1.5}, s);
    for (double tau : {-7.0, -3.3, 0.0, 0.37, 2.0, 6.9}) {
        for (double d : {0.0, 0.6, 1.2, 1.9}) {
            double want = 0;
            for (int i = -12; i <= 12; ++i) {
                double slope;
                want += spotProfile(std::sqrt(d * d + (tau + 0.5 * i) * (tau + 0.5 * i)), 1.5, slope);
            }
            want /= 25.0;
            float got = 0;
            t.add(tau, d, 1.0f, &got);
            EXPECT_NEAR(got, want, 0.01) << "tau " << tau << " d " << d;
        }
    }
    float outside = 0;
    t.add(t.tauMax() + 0.1, 0.0, 1.0f, &outside);
    t.add(0.0, t.reach() + 0.01, 1.0f, &outside);
    EXPECT_EQ(outside, 0.0f);
}

TEST(Splat, AgreesWithNaiveOnTheSameSpots)
{
    // A small tabbed jet (diverging, with vortices), three widths with halos: every channel of the
    // splat correlates with the naive gather ≥ 0.9 where either is non-zero, for the box and exp
    // kernels; in uniform flow it is exact to interpolation. The exp kernel's bounds are tight
    // (measured 0.9905 / 0.9699 at least): without the flow map carried along the line (offsets
    // not transported, G = I) it still reaches 0.9685 / 0.9576, and must fail.
    struct Case
    {
        const char* preset;
        KernelType kernel;
        double minLine, minHalo;
    };
    for (const Case& c : {Case{"tabbed-jet", KernelType::Box, 0.95, 0.9}, Case{"tabbed-jet", KernelType::Exp, 0.985, 0.96},
                          Case{"uniform", KernelType::Box, 0.995, 0.99}}) {
        const VelocityField field(makePresetField(c.preset, openvdb::Coord(32, 32, 48)).velocity);
        const OutputDomain domain(field, 2);
        const SpotSet set = poissonSpots(domain, 10.0, 7);
        LicSettings s;
        s.length = 12;
        s.kernel = c.kernel;
        s.engine = EngineType::Naive;
        const LicResult naive = convolveSpots(field, domain, set, {1.0, 1.5, 2.0}, 2.0, s);
        s.engine = EngineType::Splat;
        const LicResult splat = convolveSpots(field, domain, set, {1.0, 1.5, 2.0}, 2.0, s);
        for (int ch = 0; ch < 6; ++ch) {
            const double r = correlation(domain, naive.channels[std::size_t(ch)], splat.channels[std::size_t(ch)]);
            std::printf("%s %s channel %d: splat vs naive correlation %.4f\n", c.preset, toString(c.kernel), ch, r);
            EXPECT_GE(r, ch < 3 ? c.minLine : c.minHalo) << c.preset << " " << toString(c.kernel) << " channel " << ch;
        }
    }
}

TEST(Splat, LoopFramesAgreeWithNaiveForBothKernels)
{
    // The ripple sums of a loop (box and exp kernels), composed into frames 1 and 3 of 8: the
    // splat's frames correlate with the naive gather's ≥ 0.9 on the lines and the halos.
    for (KernelType k : {KernelType::Box, KernelType::Exp}) {
        const VelocityField field(makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36)).velocity);
        const OutputDomain domain(field, 2);
        const SpotSet set = poissonSpots(domain, 8.0, 11);
        LicSettings s;
        s.length = 10;
        s.kernel = k;
        s.ripple = true;
        s.engine = EngineType::Naive;
        const LicResult naive = convolveSpots(field, domain, set, {1.5}, 2.0, s);
        s.engine = EngineType::Splat;
        const LicResult splat = convolveSpots(field, domain, set, {1.5}, 2.0, s);
        ASSERT_EQ(splat.channels.size(), 8u); // 2 channels × (A, Re Z, Im Z) + Re N, Im N
        for (int f : {1, 3}) {
            for (int ch = 0; ch < 2; ++ch) {
                const double r = correlation(domain, composeFrame(naive, 2, ch, f, 8), composeFrame(splat, 2, ch, f, 8));
                std::printf("%s loop frame %d channel %d: splat vs naive %.4f\n", toString(k), f, ch, r);
                EXPECT_GE(r, 0.9) << toString(k) << " frame " << f << " channel " << ch;
            }
        }
        // Seamless: the splat loop's step from frame 8 back to frame 1 changes the lines and halos
        // as much as its other steps do (within ×0.5 … ×1.5 of their mean), no jump, no stall.
        for (int ch = 0; ch < 2; ++ch) {
            std::vector<std::vector<float>> frames;
            for (int f = 1; f <= 8; ++f) frames.push_back(composeFrame(splat, 2, ch, f, 8));
            double step = 0;
            for (int f = 0; f + 1 < 8; ++f) step += meanAbsDiff(domain, frames[std::size_t(f)], frames[std::size_t(f + 1)]) / 7.0;
            const double seam = meanAbsDiff(domain, frames[7], frames[0]);
            std::printf("%s splat loop channel %d: mean step %.5f, seam step %.5f\n", toString(k), ch, step, seam);
            EXPECT_GT(step, 1e-4) << toString(k) << " channel " << ch << ": the frames do not change";
            EXPECT_LE(seam, 1.5 * step) << toString(k) << " channel " << ch << ": a jump at the seam";
            EXPECT_GE(seam, 0.5 * step) << toString(k) << " channel " << ch << ": a stall at the seam";
        }
    }
}

TEST(Splat, ManyBricksAreBitIdenticalForOneToFourThreads)
{
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 4);
    const VelocityField field(makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36)).velocity);
    const OutputDomain domain(field, 2);
    const SpotSet set = poissonSpots(domain, 7.0, 3);
    for (bool ripple : {false, true}) {
        LicSettings s;
        s.engine = EngineType::Splat;
        s.length = 8;
        s.brick = 16;
        s.ripple = ripple;
        std::vector<std::vector<float>> ref;
        for (int threads : {1, 2, 3, 4}) {
            s.threads = threads;
            const LicResult r = convolveSpots(field, domain, set, {1.0, 2.0}, 2.0, s);
            EXPECT_GT(r.stats.bricks, 20u);
            if (threads == 1) {
                ref = r.channels;
                continue;
            }
            for (std::size_t k = 0; k < ref.size(); ++k)
                EXPECT_EQ(0, std::memcmp(ref[k].data(), r.channels[k].data(), ref[k].size() * sizeof(float)))
                    << "channel " << k << ", " << threads << " threads, ripple " << ripple;
        }
    }
}

TEST(Splat, WorkFollowsTheLinesNotTheBox)
{
    // The same 27 spots in a box 8× larger: the same streamlines, the same deposits, and only the
    // bricks the footprints reach are visited.
    LicSettings s;
    s.engine = EngineType::Splat;
    s.length = 6;
    s.brick = 16;
    LicStats small, large;
    std::size_t smallBricks = 0, largeBricks = 0;
    for (int n : {16, 32}) {
        const VelocityField field(makePresetField("uniform", openvdb::Coord(n)).velocity);
        const OutputDomain domain(field, 2);
        SpotSet set;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 3; ++k) set.centers.emplace_back(10.3 + 6 * i, 9.7 + 6 * j, 10.1 + 6 * k);
        set.weights.assign(set.centers.size(), 1.0f);
        const LicResult r = convolveSpots(field, domain, set, {1.0}, 2.0, s);
        (n == 16 ? small : large) = r.stats;
        (n == 16 ? smallBricks : largeBricks) = BrickLayout(domain, 16).size();
    }
    EXPECT_EQ(largeBricks, 8 * smallBricks);
    EXPECT_EQ(small.streamlines, 27u);
    EXPECT_EQ(large.streamlines, 27u);
    EXPECT_GT(small.deposits, 5000u);
    // In the small box the lines of the outermost spots end at the wall; in the large one they
    // run on, so the large box deposits a little more, never more than the longer lines allow.
    EXPECT_GE(large.deposits, small.deposits);
    EXPECT_LT(double(large.deposits), 1.6 * double(small.deposits));
    EXPECT_LE(large.bricks, 27u); // of 64: only where footprints reach
}

TEST(Splat, ALoopTracesTheSameLinesAsAStill)
{
    SmallJetSpots jet(7.0, 5);
    const auto& [field, domain, set, unused] = jet;
    LicSettings& s = jet.settings;
    const LicResult still = convolveSpots(field, domain, set, {1.0}, 2.0, s);
    s.ripple = true;
    const LicResult loop = convolveSpots(field, domain, set, {1.0}, 2.0, s);
    ASSERT_EQ(loop.channels.size(), 8u);
    EXPECT_EQ(loop.stats.samples, still.stats.samples);
    EXPECT_EQ(loop.stats.deposits, still.stats.deposits);
    for (int c = 0; c < 2; ++c)
        EXPECT_EQ(0, std::memcmp(loop.channels[std::size_t(c)].data(), still.channels[std::size_t(c)].data(),
                                 still.channels[0].size() * sizeof(float)));
}

TEST(Splat, NoiseIsRefused)
{
    const VelocityField field(lictest::abcField(8));
    const OutputDomain domain(field, 2);
    LicSettings s;
    s.engine = EngineType::Splat;
    EXPECT_THROW(convolve(field, domain, ConstantTexture(1.0f), s), InputError);
}

namespace {

/// Value of a slot-indexed volume at a fractional output index point (trilinear; inactive or
/// outside corners count 0).
double sampleAt(const OutputDomain& d, const std::vector<float>& v, const openvdb::Vec3d& p)
{
    const openvdb::Coord c(int(std::floor(p[0])), int(std::floor(p[1])), int(std::floor(p[2])));
    const openvdb::Vec3d t = p - c.asVec3d();
    double out = 0;
    for (int k = 0; k < 8; ++k) {
        const openvdb::Coord q = c.offsetBy(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        const double w = ((k & 1) ? t[0] : 1 - t[0]) * (((k >> 1) & 1) ? t[1] : 1 - t[1]) * (((k >> 2) & 1) ? t[2] : 1 - t[2]);
        const std::int64_t s = d.slotOf(q);
        if (s >= 0) out += w * double(v[std::size_t(s)]);
    }
    return out;
}

/// The shift s (output voxels, steps of 0.125 in [−4, 8]) along the local flow that best maps
/// frame `a` onto frame `b`: min Σ (b(x) − a(x − s·u(x)))² over the voxels where b or a is lit.
double bestShift(const VelocityField& field, const OutputDomain& d, const std::vector<float>& a,
                 const std::vector<float>& b)
{
    std::vector<std::size_t> slots;
    std::vector<openvdb::Vec3d> dirs;
    for (std::size_t s = 0; s < a.size(); ++s) {
        if (!d.isActive(s) || (a[s] <= 0.01f && b[s] <= 0.01f)) continue;
        openvdb::Vec3d v;
        if (!field.sample(d.worldOf(d.coordOf(s)), v) || v.length() == 0) continue;
        slots.push_back(s);
        dirs.push_back(v / v.length());
    }
    double best = 0, bestErr = 1e300;
    for (double sh = -4; sh <= 8.0001; sh += 0.125) {
        double err = 0;
        for (std::size_t i = 0; i < slots.size(); ++i) {
            const double e = double(b[slots[i]]) - sampleAt(d, a, d.coordOf(slots[i]).asVec3d() - dirs[i] * sh);
            err += e * e;
        }
        if (err < bestErr) bestErr = err, best = sh;
    }
    return best;
}


} // namespace

TEST(SplatComets, TravelDownstreamAtOnePaceAndLoop)
{
    // Uniform +x flow, Poisson spots 6 apart, radius 1, length 12; box and exp kernels, 8 and 24
    // frames; the splat and the fast engine. Every consecutive pair of frames, the seam (frame N →
    // frame 1) included, is best matched by one shift downstream: P / N (cometSpacing) within ±1
    // voxel. The line channel's mean (the frame's brightness) stays within ±5 %.
    const VelocityField field(makePresetField("uniform", openvdb::Coord(160, 20, 20)).velocity);
    const OutputDomain domain(field, 1);
    const SpotSet set = poissonSpots(domain, 6.0, 3);
    for (EngineType e : {EngineType::Splat, EngineType::Fast})
    for (KernelType k : {KernelType::Box, KernelType::Exp}) {
        for (int N : {8, 24}) {
            LicSettings s;
            s.engine = e;
            s.length = 12;
            s.kernel = k;
            s.decay = 0.85;
            s.comets = N;
            const LicResult r = convolveSpots(field, domain, set, {1.0}, 2.0, s);
            ASSERT_EQ(r.channels.size(), std::size_t(2 * N)); // lines and halos per frame
            const double expect = cometSpacing(s, 2.0) / double(N);
            std::vector<double> means;
            for (int f = 0; f < N; ++f) means.push_back(lictest::meanOverActive(domain, r.channels[std::size_t(2 * f)]));
            double avg = 0;
            for (double m : means) avg += m / double(N);
            for (int f = 0; f < N; ++f) {
                const int g = (f + 1) % N;
                const double shift = bestShift(field, domain, r.channels[std::size_t(2 * f)], r.channels[std::size_t(2 * g)]);
                const std::string what = std::string(toString(e)) + " " + toString(k) + " " + std::to_string(N) + " frames";
                if (f == 0 || f == N - 1)
                    std::printf("%s: frame %d -> %d best shift %.3f (P/N %.3f), mean %.5f\n", what.c_str(), f + 1, g + 1,
                                shift, expect, means[std::size_t(f)]);
                EXPECT_GT(shift, 0.0) << what << ", pair " << f + 1;
                EXPECT_NEAR(shift, expect, 1.0) << what << ", pair " << f + 1 << " -> " << g + 1;
                EXPECT_NEAR(means[std::size_t(f)], avg, 0.05 * avg) << what << ", frame " << f + 1;
            }
        }
    }
}

TEST(SplatComets, MoveDownstreamInTheTabbedJet)
{
    // In the curved, diverging jet the comets move along the local flow: every consecutive pair's
    // best shift along the flow is downstream (the frames' moving part: each minus the loop mean),
    // with the splat engine and with the fast one, whose frames show the same comets.
    const VelocityField field(makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36)).velocity);
    const OutputDomain domain(field, 2);
    const SpotSet set = poissonSpots(domain, 8.0, 11);
    std::vector<std::vector<float>> splatFrames;
    for (EngineType e : {EngineType::Splat, EngineType::Fast}) {
        LicSettings s;
        s.engine = e;
        s.length = 6;
        s.comets = 8;
        const LicResult r = convolveSpots(field, domain, set, {1.5}, 2.0, s);
        if (e == EngineType::Splat) {
            splatFrames = r.channels;
        } else {
            for (int f = 0; f < 8; ++f) {
                const double c = correlation(domain, splatFrames[std::size_t(2 * f)], r.channels[std::size_t(2 * f)]);
                std::printf("tabbed jet frame %d: fast vs splat correlation %.3f\n", f + 1, c);
                EXPECT_GT(c, 0.9) << "frame " << f + 1;
            }
        }
        const std::size_t V = r.channels[0].size();
        std::vector<float> mean(V, 0.0f);
        for (int f = 0; f < 8; ++f)
            for (std::size_t i = 0; i < V; ++i) mean[i] += r.channels[std::size_t(2 * f)][i] / 8.0f;
        std::vector<std::vector<float>> moving(8, std::vector<float>(V));
        for (int f = 0; f < 8; ++f)
            for (std::size_t i = 0; i < V; ++i) moving[std::size_t(f)][i] = r.channels[std::size_t(2 * f)][i] - mean[i];
        const double expect = cometSpacing(s, 3.0) / 8.0;
        for (int f = 0; f < 8; ++f) {
            const double shift = bestShift(field, domain, moving[std::size_t(f)], moving[std::size_t((f + 1) % 8)]);
            std::printf("%s tabbed jet frame %d -> %d: best shift along the flow %.3f (P/N %.3f)\n", toString(e), f + 1,
                        (f + 1) % 8 + 1, shift, expect);
            EXPECT_GT(shift, 0.5 * expect) << toString(e) << " pair " << f + 1;
            EXPECT_LT(shift, 1.5 * expect + 1.0) << toString(e) << " pair " << f + 1;
        }
    }
}

TEST(SplatComets, TheBrickSizeChangesNoValue)
{
    // Splat bricks only split where deposits land (each footprint is rasterised by every brick it
    // reaches, from the one trace, in spot order), so a comet loop in 32³ bricks (their default:
    // N·C accumulators per voxel) has the same bits as in 16³ or 64³ bricks.
    SmallJetSpots jet(7.0, 5);
    const auto& [field, domain, set, unused] = jet;
    LicSettings& s = jet.settings;
    s.comets = 6;
    EXPECT_EQ(brickDim(s), 32);
    std::vector<std::vector<float>> ref;
    for (int brick : {0, 16, 64}) {
        s.brick = brick;
        const LicResult r = convolveSpots(field, domain, set, {1.0, 2.0}, 2.0, s);
        EXPECT_EQ(r.stats.brickDim, brick == 0 ? 32 : brick);
        if (brick == 0) {
            ref = r.channels;
            continue;
        }
        ASSERT_EQ(r.channels.size(), ref.size());
        for (std::size_t k = 0; k < ref.size(); ++k)
            EXPECT_EQ(0, std::memcmp(ref[k].data(), r.channels[k].data(), ref[k].size() * sizeof(float)))
                << "channel " << k << ", " << brick << "³ bricks";
    }
    s.comets = 0; // stills keep 64³ bricks
    EXPECT_EQ(brickDim(s), 64);
}

TEST(SplatComets, OneTraceServesEveryFrameAndThreadsAgree)
{
    // A comet loop traces one line per spot, as a still does (longer: the train's extent), and is
    // bit-identical for 1 to 3 threads; so is the fast engine's.
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 3);
    const VelocityField field(makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36)).velocity);
    const OutputDomain domain(field, 2);
    const SpotSet set = poissonSpots(domain, 7.0, 5);
    LicSettings s;
    s.length = 8;
    s.brick = 16;
    s.comets = 6;
    for (EngineType e : {EngineType::Splat, EngineType::Fast}) {
        s.engine = e;
        std::vector<std::vector<float>> ref;
        for (int threads : {1, 2, 3}) {
            s.threads = threads;
            const LicResult r = convolveSpots(field, domain, set, {1.0, 2.0}, 2.0, s);
            if (e == EngineType::Splat) { // one line per spot
                EXPECT_EQ(r.stats.streamlines, set.centers.size());
            }
            ASSERT_EQ(r.channels.size(), 6u * 4u);
            if (threads == 1) {
                ref = r.channels;
                continue;
            }
            for (std::size_t k = 0; k < ref.size(); ++k)
                EXPECT_EQ(0, std::memcmp(ref[k].data(), r.channels[k].data(), ref[k].size() * sizeof(float)))
                    << toString(e) << ": channel " << k << ", " << threads << " threads";
        }
    }
    // The comets are refused by the naive engine, and with the ripple sums.
    s.engine = EngineType::Naive;
    EXPECT_THROW(s.validate(), InputError);
    s.engine = EngineType::Splat;
    s.ripple = true;
    EXPECT_THROW(s.validate(), InputError);
}

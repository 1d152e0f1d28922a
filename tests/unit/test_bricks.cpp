// Bricks: the layout, brick independence (a brick's result depends only on the brick), bit-identical
// output for any thread count over many bricks, no seams at brick faces, and the one-trace claim
// of cyclic loops.
#include "lic/composite/Animation.h"
#include "lic/field/Bricks.h"
#include "lic/composite/Compositor.h"
#include "lic/composite/Contrast.h"
#include "lic/engine/Engine.h"
#include "lic/engine/Gather.h"
#include "lic/texture/Noise.h"
#include "lic/texture/Spots.h"

#include "TestFields.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstring>
#include <map>
#include <mutex>

using namespace lic;

namespace {

/// Every brick's channels from convolveBricks(), keyed by brick number.
std::map<std::size_t, std::vector<float>> collect(const VelocityField& field, const OutputDomain& domain,
                                                  const BrickLayout& layout, NoiseBrickSource& noise,
                                                  const LicSettings& s, LicStats* stats = nullptr)
{
    std::map<std::size_t, std::vector<float>> out;
    std::mutex m;
    const LicStats st = convolveBricks(field, domain, layout, noise, s, nullProgress(), [&](const BrickChannels& b) {
        const std::size_t n = b.brick->blocks.size() * std::size_t(b.channels) * OutputDomain::kBlockVoxels;
        const std::lock_guard lock(m);
        out[b.index].assign(b.values, b.values + n);
    });
    if (stats) *stats = st;
    return out;
}

/// An ABC flow (48³ output voxels) in bricks of 16: 27 bricks, convolved with length 8 on one thread.
struct AbcBricks
{
    VelocityField field{lictest::abcField(24)};
    OutputDomain domain{field, 2};
    LicSettings s = [] {
        LicSettings t;
        t.length = 8;
        t.brick = 16;
        t.threads = 1;
        return t;
    }();
    BrickLayout layout{domain, 16};
};

/// Poisson spots 5 voxels apart over the whole output box, weight 1.
SpotSet poissonSpots(const OutputDomain& domain)
{
    SpotSet spots;
    spots.centers = placeSpots({SpotDistribution::Poisson, 5.0, 0.25, 3},
                               openvdb::BBoxd(domain.indexBBox().min().asVec3d(), domain.indexBBox().max().asVec3d()));
    spots.weights.assign(spots.centers.size(), 1.0f);
    return spots;
}

template<typename A>
bool sameBits(const std::vector<float, A>& a, const std::vector<float>& b)
{
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

} // namespace

TEST(Bricks, LayoutCoversEveryBlockOnceWithAlignedCubes)
{
    VelocityField field(lictest::abcField(20)); // 40³ output: 5³ blocks
    OutputDomain domain(field, 2);
    for (int dim : {8, 16, 24, 64}) {
        const BrickLayout layout(domain, dim);
        std::vector<int> seen(domain.blockCount(), 0);
        std::uint64_t voxels = 0;
        for (const Brick& b : layout.bricks()) {
            EXPECT_EQ(b.box.dim(), openvdb::Coord(dim));
            for (int a = 0; a < 3; ++a) EXPECT_EQ(((b.box.min()[a] % dim) + dim) % dim, 0);
            for (std::uint32_t blk : b.blocks) {
                ++seen[blk];
                EXPECT_TRUE(b.box.isInside(domain.blockOrigin(blk))) << "brick " << dim;
            }
            voxels += b.activeVoxels;
        }
        EXPECT_EQ(voxels, domain.activeVoxelCount());
        for (int c : seen) EXPECT_EQ(c, 1);
    }
    EXPECT_EQ(BrickLayout(domain, 8).size(), 125u);
    EXPECT_EQ(BrickLayout(domain, 64).size(), 1u);
    EXPECT_THROW(BrickLayout(domain, 12), InputError);
    EXPECT_THROW(BrickLayout(domain, 0), InputError);
}

TEST(Bricks, ABricksResultDependsOnlyOnTheBrick)
{
    // Each brick convolved alone, with fresh buffers, in reverse order, gives the very bits it
    // gave inside a whole-volume run with reused buffers; and the per-brick noise (with its ghost
    // margin) gives what one noise texture over the whole volume gives.
    const AbcBricks abc;
    const auto& [field, domain, s, layout] = abc;
    ASSERT_GT(layout.size(), 20u);
    NoiseBrickSource noise(9, NoiseFilter::Binomial, ghostMargin(s));
    const auto whole = collect(field, domain, layout, noise, s);
    ASSERT_EQ(whole.size(), layout.size());
    for (std::size_t i = layout.size(); i-- > 0;) {
        NoiseBrickSource fresh(9, NoiseFilter::Binomial, ghostMargin(s));
        FastEngine::Scratch scratch;
        ScratchVector<float> out;
        LicStats st;
        FastEngine::brick<NoiseTexture, false>(field, domain, layout[i], fresh(layout[i]), s, scratch, out, st,
                                               nullProgress());
        ASSERT_TRUE(sameBits(out, whole.at(i))) << "brick " << i;
    }
    // A share of the bricks (as one process of a distributed bake gets) gives the same bits,
    // keyed by the same ids.
    const BrickLayout share = layout.subset({5, 1, 17});
    ASSERT_EQ(share.size(), 3u);
    NoiseBrickSource shareNoise(9, NoiseFilter::Binomial, ghostMargin(s));
    const auto part = collect(field, domain, share, shareNoise, s);
    ASSERT_EQ(part.size(), 3u);
    for (std::size_t id : {5u, 1u, 17u}) EXPECT_TRUE(sameBits(part.at(id), whole.at(id))) << "brick " << id;
    EXPECT_THROW(layout.subset({layout.size()}), InputError);

    const NoiseTexture global(9, domain.indexBBox());
    const LicResult r = convolve(field, domain, global, s);
    for (std::size_t i = 0; i < layout.size(); ++i) {
        const Brick& b = layout[i];
        for (std::size_t k = 0; k < b.blocks.size(); ++k) {
            ASSERT_EQ(0, std::memcmp(whole.at(i).data() + k * OutputDomain::kBlockVoxels,
                                     r.channels[0].data() + std::size_t(b.blocks[k]) * OutputDomain::kBlockVoxels,
                                     OutputDomain::kBlockVoxels * sizeof(float)))
                << "brick " << i << " block " << k;
        }
    }
}

TEST(Bricks, ManyBricksAreBitIdenticalForOneToFourThreads)
{
    // 48³ output in 27 bricks of 16³; 3 and 4 threads oversubscribe a 2-core machine, so bricks
    // finish in every order. Noise (fast, naive, loop) and spots with halos at two widths.
    // (TBB caps workers at the core count unless told otherwise.)
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 4);
    VelocityField field(lictest::abcField(24));
    OutputDomain domain(field, 2);
    const SpotSet spots = poissonSpots(domain);
    struct Case
    {
        const char* name;
        EngineType engine;
        bool ripple, spots;
    };
    for (const Case& c : {Case{"fast noise", EngineType::Fast, false, false}, Case{"naive noise", EngineType::Naive, false, false},
                          Case{"fast loop", EngineType::Fast, true, false}, Case{"fast spots", EngineType::Fast, false, true},
                          Case{"fast spot loop", EngineType::Fast, true, true}}) {
        LicSettings s;
        s.engine = c.engine;
        s.length = 6;
        s.brick = 16;
        s.ripple = c.ripple;
        std::vector<std::vector<float>> ref;
        LicStats refStats;
        for (int threads : {1, 2, 3, 4}) {
            s.threads = threads;
            const LicResult r = c.spots ? convolveSpots(field, domain, spots, {1.0, 2.0}, 2.0, s)
                                        : convolve(field, domain, NoiseTexture(5, domain.indexBBox()), s);
            EXPECT_EQ(r.stats.bricks, 27u);
            if (threads == 1) {
                ref = r.channels;
                refStats = r.stats;
                continue;
            }
            ASSERT_EQ(r.channels.size(), ref.size());
            for (std::size_t k = 0; k < ref.size(); ++k)
                EXPECT_TRUE(sameBits(r.channels[k], ref[k])) << c.name << ", channel " << k << ", " << threads << " threads";
            EXPECT_EQ(r.stats.samples, refStats.samples) << c.name;
            EXPECT_EQ(r.stats.streamlines, refStats.streamlines) << c.name;
            EXPECT_EQ(r.stats.deposits, refStats.deposits) << c.name;
        }
    }
}

TEST(Bricks, FastSpeculationGivesTheSequentialLines)
{
    // The fast engine traces the next seed's line ahead while a line has one side left, and
    // drops it or cuts it back once the line has deposited. Against tracing each seed's line in
    // turn: the same bits and the same counts, for both kernels, ripple sums, strides 1, 2 and
    // automatic (4), min_hits 1 to 3, short covered runs (more lone sides), spots with halos and
    // comet loops; and the speculation did run (and, somewhere, had to drop a line).
    struct Restore
    {
        ~Restore() { detail::fastSpeculation = true; }
    } restore;
    VelocityField field(lictest::abcField(20));
    OutputDomain domain(field, 2);
    const NoiseTexture noise(3, domain.indexBBox());
    const SpotSet spots = poissonSpots(domain);
    struct Case
    {
        const char* name;
        void (*set)(LicSettings&);
        bool spots;
    };
    const Case cases[] = {
        {"box", [](LicSettings&) {}, false},
        {"exp", [](LicSettings& s) { s.kernel = KernelType::Exp; }, false},
        {"ripple", [](LicSettings& s) { s.ripple = true; }, false},
        {"stride 1", [](LicSettings& s) { s.stride = 1; }, false},
        {"stride 2", [](LicSettings& s) { s.stride = 2; }, false},
        {"min_hits 1", [](LicSettings& s) { s.minHits = 1; }, false},
        {"min_hits 3, covered run 4", [](LicSettings& s) { s.minHits = 3, s.coveredRun = 4; }, false},
        {"length 20, covered run 8", [](LicSettings& s) { s.length = 20, s.coveredRun = 8; }, false},
        {"spots", [](LicSettings&) {}, true},
        {"spot comets", [](LicSettings& s) { s.comets = 6; }, true},
    };
    std::uint64_t dropped = 0;
    for (const Case& c : cases) {
        LicSettings s;
        s.length = 8;
        s.brick = 16;
        s.threads = 2;
        c.set(s);
        auto run = [&](bool speculate) {
            detail::fastSpeculation = speculate;
            return c.spots ? convolveSpots(field, domain, spots, {1.0, 2.0}, 2.0, s) : convolve(field, domain, noise, s);
        };
        const LicResult seq = run(false), spec = run(true);
        EXPECT_EQ(seq.stats.speculated, 0u) << c.name;
        EXPECT_GT(spec.stats.speculated, spec.stats.streamlines / 10) << c.name;
        EXPECT_LT(spec.stats.dropped, spec.stats.speculated) << c.name;
        dropped += spec.stats.dropped;
        EXPECT_EQ(spec.stats.streamlines, seq.stats.streamlines) << c.name;
        EXPECT_EQ(spec.stats.samples, seq.stats.samples) << c.name;
        EXPECT_EQ(spec.stats.deposits, seq.stats.deposits) << c.name;
        ASSERT_EQ(spec.channels.size(), seq.channels.size()) << c.name;
        for (std::size_t k = 0; k < seq.channels.size(); ++k)
            EXPECT_TRUE(sameBits(spec.channels[k], seq.channels[k])) << c.name << ", channel " << k;
    }
    EXPECT_GT(dropped, 0u);
    // RK45 traces each side alone in world space: no speculation.
    LicSettings s;
    s.length = 8;
    s.integrator = Integrator::RK45;
    EXPECT_EQ(convolve(field, domain, noise, s).stats.speculated, 0u);
}

TEST(Bricks, NoSeamAtBrickFaces)
{
    // Against the naive reference, voxels next to a brick face are no worse than voxels inside a
    // brick: 16³ bricks on a 64³ output put a face every 16 voxels on each axis.
    VelocityField field(lictest::abcField(32));
    OutputDomain domain(field, 2);
    const NoiseTexture noise(7, domain.indexBBox());
    LicSettings s;
    s.engine = EngineType::Naive;
    LicResult naive = convolve(field, domain, noise, s);
    s.engine = EngineType::Fast;
    s.brick = 16;
    LicResult fast = convolve(field, domain, noise, s);
    contrastStretch(domain, naive.channels[0]);
    contrastStretch(domain, fast.channels[0]);
    double face = 0, faceN = 0, inner = 0, innerN = 0;
    for (std::size_t i = 0; i < naive.channels[0].size(); ++i) {
        if (!domain.isActive(i)) continue;
        const openvdb::Coord c = domain.coordOf(i);
        bool atFace = false;
        for (int a = 0; a < 3; ++a) {
            const int m = ((c[a] % 16) + 16) % 16;
            const bool domainEdge = c[a] < 16 ? m == 0 : (c[a] > 47 && m == 15);
            atFace = atFace || ((m == 0 || m == 15) && !domainEdge);
        }
        const double d = std::abs(double(naive.channels[0][i]) - fast.channels[0][i]);
        (atFace ? face : inner) += d;
        (atFace ? faceN : innerN) += 1;
    }
    face /= faceN;
    inner /= innerN;
    std::printf("mean |fast - naive|: voxels at brick faces %.4f, inside bricks %.4f (ratio %.3f)\n", face, inner,
                face / inner);
    EXPECT_GT(faceN, 10000);
    EXPECT_LT(face, 1.15 * inner);
    EXPECT_LT(face, 0.02);
}

TEST(Bricks, ALoopTracesTheSameStreamlinesAsAStill)
{
    // One trace serves every frame: the ripple run traces exactly the still's streamlines (same
    // counts), and its plain channel is the still's result bit for bit.
    VelocityField field(lictest::abcField(20));
    OutputDomain domain(field, 2);
    const NoiseTexture noise(4, domain.indexBBox());
    LicSettings s;
    s.length = 8;
    s.brick = 16;
    const LicResult still = convolve(field, domain, noise, s);
    s.ripple = true;
    const LicResult loop = convolve(field, domain, noise, s);
    ASSERT_EQ(loop.channels.size(), 5u);
    EXPECT_EQ(loop.stats.streamlines, still.stats.streamlines);
    EXPECT_EQ(loop.stats.samples, still.stats.samples);
    EXPECT_EQ(loop.stats.deposits, still.stats.deposits);
    EXPECT_TRUE(sameBits(loop.channels[0], still.channels[0]));
}

TEST(Bricks, ContrastStatisticsAreTheSameBitsInAnyBrickOrder)
{
    // The compositor's statistics of a noise bake (what the contrast stretch maps onto [0, 1]) do
    // not depend on the order the bricks arrive in: the same bricks fed forwards, backwards and
    // interleaved give the same mean and standard deviation to the last bit, and the first frame's
    // density grids are identical. Summing as bricks arrive would differ in the last bits.
    const AbcBricks abc;
    const auto& [field, domain, s, layout] = abc;
    NoiseBrickSource noise(9, NoiseFilter::Binomial, ghostMargin(s));
    const auto bricks = collect(field, domain, layout, noise, s);
    ASSERT_EQ(bricks.size(), layout.size());
    std::vector<std::size_t> forwards(layout.size());
    for (std::size_t i = 0; i < forwards.size(); ++i) forwards[i] = i;
    std::vector<std::size_t> backwards(forwards.rbegin(), forwards.rend()), interleaved;
    for (std::size_t i = 0; i < forwards.size(); i += 2) interleaved.push_back(forwards[i]);
    for (std::size_t i = 1; i < forwards.size(); i += 2) interleaved.push_back(forwards[i]);
    struct Result
    {
        ChannelStats raw;
        openvdb::GridPtrVec grids;
    };
    const auto composite = [&](const std::vector<std::size_t>& order) {
        CompositeSettings cs;
        Compositor c(cs, {}, field, domain, layout);
        for (const std::size_t id : order) {
            BrickChannels b;
            b.index = id;
            b.brick = &layout[id];
            b.channels = 1;
            b.values = bricks.at(id).data();
            c.consume(b);
        }
        c.finish();
        return Result{c.rawStats(), c.frame(1)};
    };
    const Result a = composite(forwards);
    EXPECT_GT(a.raw.stddev, 0.0);
    for (const auto* order : {&backwards, &interleaved}) {
        const Result b = composite(*order);
        EXPECT_EQ(std::memcmp(&a.raw.mean, &b.raw.mean, sizeof(double)), 0) << a.raw.mean << " vs " << b.raw.mean;
        EXPECT_EQ(std::memcmp(&a.raw.stddev, &b.raw.stddev, sizeof(double)), 0) << a.raw.stddev << " vs " << b.raw.stddev;
        ASSERT_EQ(a.grids.size(), b.grids.size());
        const auto& da = static_cast<const openvdb::FloatGrid&>(*a.grids[0]);
        const auto& db = static_cast<const openvdb::FloatGrid&>(*b.grids[0]);
        EXPECT_EQ(da.activeVoxelCount(), db.activeVoxelCount());
        std::size_t differ = 0;
        for (auto it = da.cbeginValueOn(); it; ++it) differ += db.tree().getValue(it.getCoord()) != *it;
        EXPECT_EQ(differ, 0u) << "density voxels differ with another brick order";
    }
}

// The streaming bake end to end (vdbexport::bake): outputs of many bricks are bit-identical for
// 1, 2, 3 and 4 threads in every grid and every loop frame; halo ≥ density on every voxel of a
// bake; a loop traces the same streamlines as a still; streamed percentiles are exact.
#include "vdbexport/bake/Bake.h"

#include "lic/field/ScalarField.h"

#include "ManifestDigests.h"
#include "TempDirSuite.h"

#include "lic/util/Error.h"
#include "lic/engine/Kernels.h"
#include "lic/field/Field.h"
#include "lic/field/Presets.h"
#include "lic/field/Scalars.h"

#include <gtest/gtest.h>
#include <chrono>
#include <tbb/parallel_for.h>
#include <openvdb/io/File.h>
#include <tbb/global_control.h>
#include <tbb/task_scheduler_observer.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <mutex>
#include <optional>
#include <thread>
#include <set>

namespace fs = std::filesystem;

namespace {

class StreamBake : public lictest::TempDirSuite<StreamBake>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("stream");
        lictest::writePresetField(sDir / "jet.vdb", "tabbed-jet", openvdb::Coord(24, 24, 36));
    }

    /// Many bricks: a 48×48×72 output in 16³ bricks.
    static vdbexport::Recipe recipe(const std::string& out)
    {
        vdbexport::Recipe r;
        r.field.path = (sDir / "jet.vdb").string();
        r.output.path = (sDir / out).string();
        r.lic.length = 8;
        r.lic.brick = 16;
        return r;
    }
    static vdbexport::Recipe spotRecipe(const std::string& out)
    {
        vdbexport::Recipe r = recipe(out);
        r.input.type = "spots";
        r.input.spacing = 7;
        r.input.radii = {1.0, 1.5, 2.0};
        r.width = vdbexport::WidthSpec{"speed", std::nullopt, true};
        r.color = vdbexport::ColorSpec{"vorticity", "heated-object", std::nullopt};
        r.output.grids.setKey("write_tangent", true);
        r.output.grids.setKey("write_series", true);
        return r;
    }
};

openvdb::GridPtrVec readAll(const std::string& path)
{
    openvdb::io::File file(path);
    file.open();
    openvdb::GridPtrVec grids;
    for (auto it = file.beginName(); it != file.endName(); ++it) grids.push_back(file.readGrid(it.gridName()));
    return grids;
}

/// Same topology and the same bits in every active voxel.
template<typename GridT>
bool sameGrid(const openvdb::GridBase& a, const openvdb::GridBase& b)
{
    const auto& ga = static_cast<const GridT&>(a);
    const auto& gb = static_cast<const GridT&>(b);
    if (!ga.tree().hasSameTopology(gb.tree())) return false;
    auto acc = gb.getConstAccessor();
    for (auto it = ga.cbeginValueOn(); it; ++it) {
        const auto va = *it, vb = acc.getValue(it.getCoord());
        if (std::memcmp(&va, &vb, sizeof va) != 0) return false;
    }
    return true;
}

void expectSameFiles(const std::string& a, const std::string& b, const std::string& what)
{
    const openvdb::GridPtrVec ga = readAll(a), gb = readAll(b);
    ASSERT_EQ(ga.size(), gb.size()) << what;
    for (std::size_t i = 0; i < ga.size(); ++i) {
        ASSERT_EQ(ga[i]->getName(), gb[i]->getName()) << what;
        const bool same = ga[i]->isType<openvdb::FloatGrid>() ? sameGrid<openvdb::FloatGrid>(*ga[i], *gb[i])
                                                              : sameGrid<openvdb::Vec3SGrid>(*ga[i], *gb[i]);
        EXPECT_TRUE(same) << what << ": grid " << ga[i]->getName() << " differs";
    }
}

/// Voxels where halo < density (there must be none), and the density voxels checked.
std::pair<std::size_t, std::size_t> haloBelowDensity(const std::string& path)
{
    openvdb::FloatGrid::Ptr density, halo;
    for (const auto& g : readAll(path)) {
        if (g->getName() == "density") density = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
        if (g->getName() == "halo") halo = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
    }
    EXPECT_TRUE(density && halo) << path;
    if (!density || !halo) return {1, 0};
    std::size_t below = 0, n = 0;
    auto acc = halo->getConstAccessor();
    for (auto it = density->cbeginValueOn(); it; ++it, ++n)
        if (acc.getValue(it.getCoord()) < *it) ++below;
    return {below, n};
}

} // namespace

TEST_F(StreamBake, EveryGridIsBitIdenticalForOneToFourThreads)
{
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 4);
    // Spots with halos, three widths by speed, colour, tangent and the width series, with the
    // splat (the default for spots) and the fast engine.
    for (const std::string engine : {"splat", "fast"}) {
        std::string first;
        for (int threads : {1, 2, 3, 4}) {
            auto r = spotRecipe("spots_" + engine + "_t" + std::to_string(threads) + ".vdb");
            r.lic.engine = engine;
            r.threads = threads;
            const auto summary = vdbexport::bake(r);
            EXPECT_GE(summary["bricks"].get<int>(), 20) << engine;
            if (threads == 1) first = r.output.path;
            else expectSameFiles(first, r.output.path, engine + " spots, " + std::to_string(threads) + " threads");
        }
    }
    // A noise loop of 4 frames with colour and tangent: every frame file, and the contrast
    // statistics to the last bit (sums merged in a fixed order, not as bricks arrive).
    std::string loop1;
    nlohmann::json stats1;
    for (int threads : {1, 3, 4}) {
        auto r = recipe("loop_t" + std::to_string(threads) + ".vdb");
        r.animation.frames = 4;
        r.color = vdbexport::ColorSpec{"speed", "viridis", std::nullopt};
        r.output.grids.setKey("write_tangent", true);
        r.threads = threads;
        const auto summary = vdbexport::bake(r);
        ASSERT_EQ(summary["files"].size(), 4u);
        const nlohmann::json stats = {summary["raw_mean"], summary["raw_stddev"]};
        if (threads == 1) {
            loop1 = r.output.path;
            stats1 = stats;
            lictest::expectManifestDigests(vdbexport::manifestPath(r.output.path), 4);
            continue;
        }
        EXPECT_EQ(stats.dump(), stats1.dump()) << threads << " threads";
        for (int f = 1; f <= 4; ++f)
            expectSameFiles(vdbexport::framePath(loop1, f, 4), vdbexport::framePath(r.output.path, f, 4),
                            "noise loop frame " + std::to_string(f));
    }
    // A spot loop: frames of line and halo.
    std::string spotLoop1;
    for (int threads : {1, 4}) {
        auto r = spotRecipe("spotloop_t" + std::to_string(threads) + ".vdb");
        r.animation.frames = 3;
        r.threads = threads;
        vdbexport::bake(r);
        if (threads == 1) {
            spotLoop1 = r.output.path;
            lictest::expectManifestDigests(vdbexport::manifestPath(r.output.path), 3);
            continue;
        }
        for (int f = 1; f <= 3; ++f)
            expectSameFiles(vdbexport::framePath(spotLoop1, f, 3), vdbexport::framePath(r.output.path, f, 3),
                            "spot loop frame " + std::to_string(f));
    }
}

/// Counts TBB worker threads that join any arena while it observes (global observer).
class WorkerCounter : public tbb::task_scheduler_observer
{
public:
    WorkerCounter() { observe(true); }
    ~WorkerCounter() override { observe(false); }
    void on_scheduler_entry(bool isWorker) override
    {
        if (!isWorker) return;
        const std::lock_guard lock(mMutex);
        mWorkers.insert(std::this_thread::get_id());
    }
    std::size_t workers()
    {
        const std::lock_guard lock(mMutex);
        return mWorkers.size();
    }

private:
    std::mutex mMutex;
    std::set<std::thread::id> mWorkers;
};

/// The one-thread check needs a process whose TBB has no workers yet (as licvdb, which sets its
/// limit before any parallel work): a worker already inside the arena when a limit is set may still
/// take tasks. This suite sets one thread before its set-up makes the input (CTest runs each test
/// in a process of its own).
class StreamBakeOneThread : public StreamBake
{
protected:
    static void SetUpTestSuite()
    {
        sOne.emplace(tbb::global_control::max_allowed_parallelism, 1);
        StreamBake::SetUpTestSuite();
    }
    static void TearDownTestSuite()
    {
        StreamBake::TearDownTestSuite();
        sOne.reset();
    }
    static inline std::optional<tbb::global_control> sOne;
};

// `threads` bounds every parallel stage of a bake (field preparation, output domain, scalar
// ranges, the convolution, compositing, a sequence's advection), not just the convolution: with
// threads = 1 no TBB worker joins in at all. The control run with all cores shows the observer
// sees workers when they do join.
TEST_F(StreamBakeOneThread, OneThreadMeansNoWorkerInAnyStage)
{
    vdbexport::Recipe spots = spotRecipe("t1_spots.vdb");
    spots.threads = 1;
    spots.roi = vdbexport::RoiSpec{"speed", {0.2, 5.0}, "pre"};
    vdbexport::Recipe noise = recipe("t1_noise.vdb");
    noise.threads = 1;
    noise.animation.frames = 3;
    noise.output.grids.setKey("write_input", true);
    noise.color = vdbexport::ColorSpec{"helicity", "viridis", std::nullopt};
    {
        WorkerCounter counter;
        vdbexport::bake(spots);
        vdbexport::bake(noise);
        EXPECT_EQ(counter.workers(), 0u) << "a stage ran on TBB workers although threads = 1";
    }
    sOne.reset(); // every core again, for the control
    if (std::thread::hardware_concurrency() >= 2) {
        WorkerCounter counter;
        vdbexport::Recipe all = recipe("t0_noise.vdb");
        all.threads = 0;
        vdbexport::bake(all);
        EXPECT_GT(counter.workers(), 0u) << "the observer saw no worker with every core allowed";
    }
}

TEST_F(StreamBake, HaloIsNeverBelowDensityInAnyVoxelOfABake)
{
    auto still = spotRecipe("halo_still.vdb");
    vdbexport::bake(still);
    const auto [below, n] = haloBelowDensity(still.output.path);
    EXPECT_GT(n, 10000u);
    EXPECT_EQ(below, 0u);
    auto post = spotRecipe("halo_post.vdb");
    post.roi = vdbexport::RoiSpec{"speed", {0.2, 2.0}, "post"};
    vdbexport::bake(post);
    EXPECT_EQ(haloBelowDensity(post.output.path).first, 0u);
    auto loop = spotRecipe("halo_loop.vdb");
    loop.animation.frames = 3;
    vdbexport::bake(loop);
    for (int f = 1; f <= 3; ++f) EXPECT_EQ(haloBelowDensity(vdbexport::framePath(loop.output.path, f, 3)).first, 0u);
}

TEST_F(StreamBake, SplatBakesAgreeWithNaiveAndKeepEveryFeature)
{
    // The same spots, three widths with halos, width by speed: the density of the splat bake
    // correlates ≥ 0.9 with the naive bake's where either is non-zero, and every line voxel lies
    // inside its halo.
    auto naive = spotRecipe("agree_naive.vdb");
    naive.lic.engine = "naive";
    naive.output.grids.setKey("write_tangent", false).setKey("write_series", false);
    naive.color.reset();
    vdbexport::bake(naive);
    auto splat = naive;
    splat.lic.engine = "splat";
    splat.output.path = (sDir / "agree_splat.vdb").string();
    const auto summary = vdbexport::bake(splat);
    EXPECT_EQ(summary["engine"], "splat");
    auto density = [](const std::string& path) {
        for (const auto& g : readAll(path))
            if (g->getName() == "density") return openvdb::gridPtrCast<openvdb::FloatGrid>(g);
        return openvdb::FloatGrid::Ptr();
    };
    const auto a = density(naive.output.path), b = density(splat.output.path);
    ASSERT_TRUE(a && b);
    double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, n = 0;
    auto visit = [&](const openvdb::FloatGrid& g, const openvdb::FloatGrid& other, bool both) {
        auto acc = other.getConstAccessor();
        for (auto it = g.cbeginValueOn(); it; ++it) {
            const double x = *it, y = acc.getValue(it.getCoord());
            if (!both && acc.isValueOn(it.getCoord())) continue; // counted from the first grid
            const double u = both ? x : y, v = both ? y : x;
            if (u <= 1e-3 && v <= 1e-3) continue;
            sx += u, sy += v, sxx += u * u, syy += v * v, sxy += u * v, n += 1;
        }
    };
    visit(*a, *b, true);
    visit(*b, *a, false);
    const double corr = (sxy - sx * sy / n) / std::sqrt((sxx - sx * sx / n) * (syy - sy * sy / n));
    std::printf("density, splat vs naive bake: correlation %.4f over %.0f voxels\n", corr, n);
    EXPECT_GE(corr, 0.9);
    EXPECT_EQ(haloBelowDensity(splat.output.path).first, 0u);

    // Every feature a spot bake has, with splat: ROI pre, surface seeding, width series, colour,
    // tangent, half floats and a loop.
    auto all = spotRecipe("splat_all.vdb");
    all.lic.engine = "splat";
    all.roi = vdbexport::RoiSpec{"speed", {0.2, 2.0}, "pre"};
    all.output.half = true;
    all.animation.frames = 3;
    const auto s2 = vdbexport::bake(all);
    ASSERT_EQ(s2["files"].size(), 3u);
    for (int f = 1; f <= 3; ++f) {
        std::set<std::string> names;
        for (const auto& g : readAll(vdbexport::framePath(all.output.path, f, 3))) {
            names.insert(g->getName());
            EXPECT_GT(g->activeVoxelCount(), 100u) << g->getName();
        }
        for (const char* want : {"density", "halo", "density_w1", "halo_w3", "color", "scalar", "tangent"})
            EXPECT_TRUE(names.count(want)) << want << " in frame " << f;
        EXPECT_EQ(haloBelowDensity(vdbexport::framePath(all.output.path, f, 3)).first, 0u);
    }
    auto surface = spotRecipe("splat_surface.vdb");
    surface.lic.engine = "splat";
    surface.input.surface = vdbexport::SurfaceSpec{"speed-gradient", 0.0};
    surface.input.radii = {1.0};
    surface.width.reset();
    surface.output.grids.setKey("write_series", false);
    const auto s3 = vdbexport::bake(surface);
    EXPECT_GT(s3["spots"]["count"].get<int>(), 10);
    EXPECT_GT(s3["density_active_voxels"].get<int>(), 1000);
}

TEST_F(StreamBake, ACometLoopsWidthSeriesHoldsEachLevelOfEachFrame)
{
    // Two widths, no width scalar: the composite is the narrowest level, so in every frame
    // density and halo are density_w1 and halo_w1 bit for bit, while the wider level differs,
    // and each level moves from frame to frame (the loop keeps every frame's levels compact
    // until it writes them).
    auto r = spotRecipe("series_loop.vdb");
    r.lic.engine = "splat";
    r.input.radii = {1.0, 2.0};
    r.width.reset();
    r.color.reset();
    r.animation.frames = 4;
    vdbexport::bake(r);
    std::vector<std::map<std::string, openvdb::GridBase::Ptr>> frames(4);
    for (int f = 1; f <= 4; ++f) {
        for (const auto& g : readAll(vdbexport::framePath(r.output.path, f, 4))) frames[std::size_t(f - 1)][g->getName()] = g;
        auto& grids = frames[std::size_t(f - 1)];
        for (const char* name : {"density", "halo", "density_w1", "halo_w1", "density_w2", "halo_w2"})
            ASSERT_TRUE(grids.count(name)) << name << " in frame " << f;
        EXPECT_GT(grids["density"]->activeVoxelCount(), 1000u);
        EXPECT_TRUE(sameGrid<openvdb::FloatGrid>(*grids["density"], *grids["density_w1"])) << "frame " << f;
        EXPECT_TRUE(sameGrid<openvdb::FloatGrid>(*grids["halo"], *grids["halo_w1"])) << "frame " << f;
        EXPECT_FALSE(sameGrid<openvdb::FloatGrid>(*grids["density_w1"], *grids["density_w2"])) << "frame " << f;
        EXPECT_FALSE(sameGrid<openvdb::FloatGrid>(*grids["halo_w2"], *grids["density_w2"])) << "frame " << f;
    }
    for (int f = 1; f < 4; ++f)
        for (const char* name : {"density_w1", "halo_w1", "density_w2", "halo_w2"})
            EXPECT_FALSE(sameGrid<openvdb::FloatGrid>(*frames[std::size_t(f - 1)][name], *frames[std::size_t(f)][name]))
                << name << " did not move from frame " << f;
}

TEST_F(StreamBake, ALoopTracesTheSameStreamlinesAsAStill)
{
    auto still = recipe("trace_still.vdb");
    const auto a = vdbexport::bake(still);
    auto loop = recipe("trace_loop.vdb");
    loop.animation.frames = 24;
    const auto b = vdbexport::bake(loop);
    EXPECT_EQ(b["files"].size(), 24u);
    EXPECT_EQ(a["streamlines"], b["streamlines"]);
    EXPECT_EQ(a["samples"], b["samples"]);
    EXPECT_EQ(a["deposits"], b["deposits"]);
    EXPECT_GT(a["streamlines"].get<std::uint64_t>(), 1000u);
}

TEST_F(StreamBake, StreamedPercentilesAreExact)
{
    const lic::PresetField f = lic::makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36));
    const lic::VelocityField field(f.velocity);
    const lic::OutputDomain domain(field, 2);
    for (const std::string name : {"speed", "vorticity"}) {
        const openvdb::FloatGrid::Ptr s = lic::deriveScalar(*f.velocity, name);
        std::vector<float> v;
        const lic::ScalarField probe(s);
        for (std::size_t b = 0; b < domain.blockCount(); ++b) {
            const auto& mask = domain.blockMask(b);
            for (auto on = mask.beginOn(); on; ++on) {
                const std::size_t off = on.pos();
                v.push_back(probe.at(domain.worldOf(domain.coordOf(b * lic::OutputDomain::kBlockVoxels + off))));
            }
        }
        auto pct = [&](double q) {
            const std::size_t k = std::min(v.size() - 1, std::size_t(q * double(v.size() - 1) + 0.5));
            std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
            return double(v[k]);
        };
        const std::array<double, 2> expected{pct(0.01), pct(0.99)};
        for (int threads : {1, 2}) {
            const auto got = lic::autoRange(probe, domain, threads);
            EXPECT_EQ(got[0], expected[0]) << name;
            EXPECT_EQ(got[1], expected[1]) << name;
        }
    }
}

TEST(ScalarSet, AbsSuffixIsTheMagnitudeOfAnyScalar)
{
    // The tabbed jet's counter-rotating vortex pairs give streamwise vorticity of both signs.
    openvdb::initialize();
    const lic::PresetField f = lic::makePresetField("tabbed-jet", openvdb::Coord(16, 16, 24));
    std::map<std::string, openvdb::FloatGrid::Ptr> file;
    for (const auto& s : f.scalars) file[s->getName()] = s;
    lic::ScalarSet set(*f.velocity, file);
    for (const std::string base : {"streamwise-vorticity", "temperature", "speed-gradient"}) {
        const auto signedGrid = set.get(base);
        const auto mag = set.get(base + "-abs");
        EXPECT_EQ(mag->getName(), base + "-abs");
        EXPECT_EQ(mag->activeVoxelCount(), signedGrid->activeVoxelCount()) << base;
        EXPECT_EQ(mag.get(), set.get(base + "-abs").get()) << base << ": computed once";
        auto acc = signedGrid->getConstAccessor();
        std::size_t negatives = 0;
        for (auto it = mag->cbeginValueOn(); it; ++it) {
            const float s = acc.getValue(it.getCoord());
            negatives += s < 0.0f;
            ASSERT_EQ(*it, std::abs(s)) << base << " at " << it.getCoord();
        }
        if (base == "streamwise-vorticity") {
            EXPECT_GT(negatives, 100u);
        }
    }
    EXPECT_THROW(set.get("no-such-grid-abs"), lic::InputError);
}

namespace {
openvdb::GridBase::Ptr readGrid(const std::string& path, const std::string& name)
{
    openvdb::io::File file(path);
    file.open();
    openvdb::GridBase::Ptr g = file.readGrid(name);
    file.close();
    return g;
}
} // namespace

TEST_F(StreamBake, VelocityGridGivesTheMotionOfTheLines)
{
    // --write-velocity: a vec3s `velocity` grid on the output's voxels, world units per second.
    // A still: the flow itself. A comet loop: the flow's direction at the comets' one speed,
    // P / N output voxels per frame at field.fps. A noise loop: the ripple's speed.
    const lic::PresetField jet = lic::makePresetField("tabbed-jet", openvdb::Coord(24, 24, 36));
    const lic::VelocityField field(jet.velocity);
    auto check = [&](const std::string& path, double speed, const std::string& what) {
        const auto density = openvdb::gridPtrCast<openvdb::FloatGrid>(readGrid(path, "density"));
        const auto velocity = openvdb::gridPtrCast<openvdb::Vec3SGrid>(readGrid(path, "velocity"));
        ASSERT_TRUE(density && velocity) << what;
        EXPECT_TRUE(velocity->tree().hasSameTopology(density->tree())) << what;
        EXPECT_EQ(velocity->getVectorType(), openvdb::VEC_CONTRAVARIANT_RELATIVE) << what;
        std::size_t n = 0, moving = 0;
        for (auto it = velocity->cbeginValueOn(); it; ++it, ++n) {
            const openvdb::Vec3d world = velocity->indexToWorld(it.getCoord());
            openvdb::Vec3d v;
            ASSERT_TRUE(field.sample(world, v)) << what;
            const openvdb::Vec3d got(*it);
            if (speed == 0) { // the flow itself
                ASSERT_LE((got - v).length(), 1e-5 * (1.0 + v.length())) << what << " at " << it.getCoord();
                continue;
            }
            if (v.length() < field.maxSpeed() * 1e-6) continue;
            ++moving;
            ASSERT_NEAR(got.length(), speed, 1e-5 * speed) << what << " at " << it.getCoord();
            ASSERT_GT(got.dot(v) / (got.length() * v.length()), 0.9999) << what << ": not along the flow";
        }
        EXPECT_GT(n, 1000u) << what;
        if (speed > 0) {
            EXPECT_GT(moving, n / 2) << what;
        }
    };
    auto still = spotRecipe("vel_still.vdb");
    still.output.grids.setKey("write_velocity", true);
    vdbexport::bake(still);
    check(still.output.path, 0.0, "spot still");

    auto loop = spotRecipe("vel_loop.vdb");
    loop.output.grids.setKey("write_velocity", true);
    loop.animation.frames = 6;
    loop.field.fps = 30;
    vdbexport::bake(loop);
    // Output voxel: field voxel / upsample 2; comet spacing from the settings the bake used.
    lic::LicSettings s;
    s.length = loop.lic.length;
    s.step = loop.lic.step;
    s.kernel = lic::KernelType::Box;
    const double voxel = jet.velocity->voxelSize()[0] / 2.0;
    const double cometSpeed = lic::cometSpacing(s, 2.0 * loop.input.haloScale) / 6.0 * voxel * 30.0; // widest halo
    for (int f = 1; f <= 6; ++f) check(vdbexport::framePath(loop.output.path, f, 6), cometSpeed, "comet loop frame " + std::to_string(f));

    auto noise = recipe("vel_noise.vdb");
    noise.output.grids.setKey("write_velocity", true);
    noise.animation.frames = 4;
    vdbexport::bake(noise);
    const double rippleSpeed = double(2 * s.halfSamples() + 1) * s.step / 4.0 * voxel * noise.field.fps;
    check(vdbexport::framePath(noise.output.path, 1, 4), rippleSpeed, "noise loop");
}

TEST_F(StreamBake, ASpotLoopThroughSqueezedLinesBakes)
{
    // The vortex ring squeezes some comet lines (run a comet spacing past the spot) to almost
    // nothing: their offset transport's determinant, expanded by column as Mat3::inverse() does,
    // came out exactly 0 where the row expansion did not, and the bake stopped with "Inversion of
    // singular 3x3 matrix". Such samples now push every voxel out of the spot's reach.
    lictest::writePresetField(sDir / "ring.vdb", "vortex-ring", openvdb::Coord(32, 32, 32), lictest::PresetGrids::Velocity);
    vdbexport::Recipe r;
    r.field.path = (sDir / "ring.vdb").string();
    r.output.path = (sDir / "ring_loop.vdb").string();
    r.input.type = "spots";
    r.input.spacing = 8;
    r.animation.frames = 3;
    ASSERT_NO_THROW(vdbexport::bake(r));
    for (int frame = 1; frame <= 3; ++frame) {
        const openvdb::GridPtrVec grids = readAll(vdbexport::framePath(r.output.path, frame, 3));
        openvdb::FloatGrid::Ptr density;
        for (const auto& g : grids)
            if (g->getName() == "density") density = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
        ASSERT_TRUE(density) << "frame " << frame;
        std::size_t lit = 0;
        for (auto it = density->cbeginValueOn(); it; ++it) {
            ASSERT_TRUE(*it >= 0.0f && *it <= 1.0f) << "frame " << frame << " at " << it.getCoord();
            lit += *it > 0.5f;
        }
        EXPECT_GT(lit, 1000u) << "frame " << frame;
    }
}

TEST_F(StreamBake, ALoopTooBigForMemoryIsRefusedBeforeItStarts)
{
    // 10 000 frames of three widths with halos: 60 000 values per voxel of a 64³ brick, on every
    // thread. Refused when planned, with the figures and what to change, and nothing written.
    ASSERT_EQ(0, ::setenv("LICVDB_READ_MEMORY_MB", "4096", 1));
    auto r = spotRecipe("too_many_frames.vdb");
    r.lic.brick = 64;
    r.animation.frames = 10000;
    try {
        vdbexport::bake(r);
        ADD_FAILURE() << "a 10000-frame comet loop was not refused";
    } catch (const lic::InputError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("animation.frames"), std::string::npos) << what;
        EXPECT_NE(what.find("60000 values per voxel"), std::string::npos) << what;
        EXPECT_NE(what.find("(4 GiB)"), std::string::npos) << what;
    }
    ::unsetenv("LICVDB_READ_MEMORY_MB");
    for (const auto& entry : fs::directory_iterator(sDir))
        EXPECT_EQ(entry.path().filename().string().find("too_many_frames"), std::string::npos) << entry.path();
}

// A spot still's leaves are sealed as its bricks finish (compressed for the file, their values
// dropped): the file must be the one whole leaves give, byte for byte but for the header's random
// UUID, for every grid a still can have (lines, halos, the width series, colour, scalar, tangent,
// velocity, input), in floats and in half floats. Loops seal the grids their frames share; noise
// stills keep whole leaves.
TEST_F(StreamBake, SealedLeavesWriteTheFileWholeLeavesWrite)
{
    auto fileBytes = [](const std::string& path) {
        std::ifstream in(path, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), {});
    };
    struct EnvGuard
    {
        ~EnvGuard() { ::unsetenv("LICVDB_SEAL_LEAVES"); }
    } guard;
    for (const bool halfFloats : {false, true}) {
        // The same path both times (the recipe, path included, is in the file's metadata).
        std::string bytes[2];
        auto r = spotRecipe(std::string("sealed") + (halfFloats ? "_half" : "") + ".vdb");
        r.output.half = halfFloats;
        r.output.grids.setKey("write_input", true);
        r.output.grids.setKey("write_velocity", true);
        for (const bool seal : {true, false}) {
            if (seal) ::unsetenv("LICVDB_SEAL_LEAVES");
            else ::setenv("LICVDB_SEAL_LEAVES", "0", 1);
            const auto summary = vdbexport::bake(r);
            EXPECT_EQ(summary["sealed_leaves"].get<bool>(), seal) << "half " << halfFloats;
            bytes[seal ? 0 : 1] = fileBytes(r.output.path);
            if (seal) {
                std::set<std::string> names;
                for (const auto& g : readAll(r.output.path)) names.insert(g->getName());
                for (const char* want :
                     {"density", "halo", "density_w3", "halo_w3", "color", "scalar", "tangent", "velocity", "input"})
                    EXPECT_TRUE(names.count(want)) << want;
            }
        }
        const std::string &a = bytes[0], &b = bytes[1];
        ASSERT_GT(a.size(), 10000u);
        ASSERT_EQ(a.size(), b.size()) << "half " << halfFloats;
        constexpr std::size_t kUuid = 21, kUuidEnd = 21 + 36; // the header's random UUID
        EXPECT_EQ(a.substr(0, kUuid), b.substr(0, kUuid));
        EXPECT_TRUE(a.substr(kUuidEnd) == b.substr(kUuidEnd)) << "half " << halfFloats << ": sealed and whole leaves differ";
    }
    // Loops seal the grids every frame shares (colour, scalar, tangent, velocity, input):
    // compressed once for all the frame files; comet loops also every frame's own grids. Every
    // frame must still be the file whole leaves give. Spot loops (comets, composed on arrival) and
    // noise loops (composed per frame).
    auto spotLoop = spotRecipe("sealed_loop.vdb");
    auto noiseLoop = recipe("sealed_noise_loop.vdb");
    for (auto* r : {&spotLoop, &noiseLoop}) {
        r->animation.frames = 3;
        r->output.grids.setKey("write_input", true);
        r->output.grids.setKey("write_velocity", true);
        r->output.grids.setKey("write_tangent", true);
        if (!r->color) r->color = vdbexport::ColorSpec{"speed", "viridis", std::nullopt};
        std::vector<std::string> frames[2], paths;
        for (const bool seal : {true, false}) {
            if (seal) ::unsetenv("LICVDB_SEAL_LEAVES");
            else ::setenv("LICVDB_SEAL_LEAVES", "0", 1);
            const auto summary = vdbexport::bake(*r);
            EXPECT_EQ(summary["sealed_leaves"].get<bool>(), seal) << r->output.path;
            // A comet loop also seals every frame's density and halo (each frame's leaves under
            // the grid's one name); a noise loop composes its frames at the end.
            std::vector<std::string> sealedGrids{"input", "tangent", "velocity", "color", "scalar"};
            if (r == &spotLoop) // three widths, each written (density_w<k>, halo_w<k>)
                sealedGrids.insert(sealedGrids.begin(), {"density", "halo", "density_w1", "density_w2", "density_w3",
                                                         "halo_w1", "halo_w2", "halo_w3"});
            if (!seal) sealedGrids.clear();
            EXPECT_EQ(summary["sealed_grids"].get<std::vector<std::string>>(), sealedGrids) << r->output.path;
            paths = summary["files"].get<std::vector<std::string>>();
            for (const auto& path : paths) frames[seal ? 0 : 1].push_back(fileBytes(path));
        }
        ASSERT_EQ(frames[0].size(), 3u) << r->output.path;
        ASSERT_EQ(frames[1].size(), 3u) << r->output.path;
        for (std::size_t f = 0; f < 3; ++f) {
            const std::string &a = frames[0][f], &b = frames[1][f];
            ASSERT_EQ(a.size(), b.size()) << r->output.path << " frame " << f + 1;
            constexpr std::size_t kUuid = 21, kUuidEnd = 21 + 36;
            EXPECT_EQ(a.substr(0, kUuid), b.substr(0, kUuid));
            EXPECT_TRUE(a.substr(kUuidEnd) == b.substr(kUuidEnd))
                << r->output.path << " frame " << f + 1 << ": sealed and whole leaves differ";
        }
        // A loop's records are spooled to an unnamed file in the output directory; without
        // O_TMPFILE to a named one removed at once: the same frames, nothing left behind.
        ::unsetenv("LICVDB_SEAL_LEAVES");
        ::setenv("LICVDB_TEST_NO_O_TMPFILE", "1", 1);
        const auto named = vdbexport::bake(*r);
        ::unsetenv("LICVDB_TEST_NO_O_TMPFILE");
        EXPECT_TRUE(named["sealed_leaves"].get<bool>());
        for (std::size_t f = 0; f < 3; ++f) {
            const std::string a = fileBytes(paths.at(f)), &b = frames[1][f];
            ASSERT_EQ(a.size(), b.size()) << r->output.path << " frame " << f + 1 << " (named spool)";
            EXPECT_TRUE(a.substr(21 + 36) == b.substr(21 + 36)) << r->output.path << " frame " << f + 1 << " (named spool)";
        }
        for (const auto& entry : fs::directory_iterator(fs::path(r->output.path).parent_path()))
            EXPECT_EQ(entry.path().filename().string().rfind(".licvdb-spool", 0), std::string::npos) << entry.path();
        // Three different frames (the loop moves), the shared grids in each.
        EXPECT_NE(frames[0][0], frames[0][1]) << r->output.path;
        std::set<std::string> names;
        for (const auto& g : readAll(paths.at(1))) names.insert(g->getName());
        for (const char* want : {"density", "color", "scalar", "tangent", "velocity", "input"})
            EXPECT_TRUE(names.count(want)) << r->output.path << ": " << want;
    }
    ::unsetenv("LICVDB_SEAL_LEAVES");
    // A noise still composes its leaves at the end: nothing to seal.
    EXPECT_FALSE(vdbexport::bake(recipe("sealed_noise.vdb"))["sealed_leaves"].get<bool>());
}

TEST_F(StreamBake, CometLoopFramesKeepTheLoopsBrightness)
{
    // Issue 55 item 4: in the written files, every frame's mean `density` and mean `halo` (over
    // the active voxels, the same set in every frame) lie within ±3 % of the loop's mean; box and
    // exp, 8 and 24 frames, splat and fast. Uniform flow 160 voxels long, Poisson spots 6 apart,
    // radius 1, halos ×2, length 12 (comet spacing P = 34 box, 22 exp: lines 5–7 P long). The
    // brightness is the sum of the comets inside the domain; a comet leaving through an end fades
    // out, so in domains only one or two P long it varies more (docs/technique.md §8).
    lictest::writePresetField(sDir / "uniform.vdb", "uniform", openvdb::Coord(160, 20, 20), lictest::PresetGrids::Velocity);
    for (const std::string engine : {"splat", "fast"})
    for (const std::string kernel : {"box", "exp"})
    for (int frames : {8, 24}) {
        vdbexport::Recipe r;
        r.field.path = (sDir / "uniform.vdb").string();
        r.output.path = (sDir / ("bright_" + engine + kernel + std::to_string(frames) + ".vdb")).string();
        r.output.upsample = 1;
        r.input.type = "spots";
        r.input.seed = 3;
        r.lic.engine = engine;
        r.lic.kernel = kernel;
        if (kernel == "exp") r.lic.decay = 0.85;
        r.lic.length = 12;
        r.animation.frames = frames;
        vdbexport::bake(r);
        const std::string what = engine + " " + kernel + " " + std::to_string(frames) + " frames";
        for (const std::string grid : {"density", "halo"}) {
            std::vector<double> means;
            openvdb::Index64 active = 0;
            for (int f = 1; f <= frames; ++f) {
                openvdb::io::File file(vdbexport::framePath(r.output.path, f, frames));
                file.open();
                const auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(grid));
                ASSERT_TRUE(g) << what << ": " << grid << " in frame " << f;
                if (f == 1) active = g->activeVoxelCount();
                ASSERT_EQ(g->activeVoxelCount(), active) << what << ": " << grid << " in frame " << f;
                double sum = 0;
                for (auto it = g->cbeginValueOn(); it; ++it) sum += double(*it);
                means.push_back(sum / double(active));
            }
            double loop = 0;
            for (double m : means) loop += m / double(frames);
            ASSERT_GT(active, 20000u) << what;
            ASSERT_GT(loop, 0.02) << what << ": " << grid;
            double worst = 0;
            for (int f = 0; f < frames; ++f) {
                worst = std::max(worst, std::abs(means[std::size_t(f)] / loop - 1.0));
                EXPECT_NEAR(means[std::size_t(f)], loop, 0.03 * loop) << what << ": " << grid << " frame " << f + 1;
            }
            std::printf("%s: %s mean %.4f, frames within %+.2f %%\n", what.c_str(), grid.c_str(), loop, 100 * worst);
        }
    }
}

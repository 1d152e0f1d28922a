// Spot bakes end to end through vdbexport::bake(): region of interest (pre and post), halos that
// enclose their lines, width series chosen by a scalar, surface-of-interest seeding, sparse output,
// and thread determinism. Fields are small (tabbed-jet at 40×40×60) so the suite runs in seconds.
#include "vdbexport/bake/Bake.h"
#include "vdbexport/io/AtomicWrite.h"

#include "lic/util/Error.h"
#include "lic/field/Presets.h"
#include "lic/field/Region.h"
#include "lic/field/Scalars.h"

#include "TempDirSuite.h"
#include "TestFields.h"

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/tools/Interpolation.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>

namespace fs = std::filesystem;

namespace {

class HaloBake : public lictest::TempDirSuite<HaloBake>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("halos");
        const lic::PresetField f = lictest::writePresetField(sDir / "jet.vdb", "tabbed-jet", openvdb::Coord(40, 40, 60));
        sVelocity = f.velocity;
        // ROI on speed: the fastest 10% of the jet's voxels (its core near the tabs).
        sSpeed = lic::deriveScalar(*f.velocity, "speed");
        std::vector<float> v;
        for (auto it = sSpeed->cbeginValueOn(); it; ++it) v.push_back(*it);
        std::sort(v.begin(), v.end());
        sRoi = {v[v.size() * 9 / 10], v.back() * 1.01};
    }

    static vdbexport::Recipe spotRecipe(const std::string& out)
    {
        vdbexport::Recipe r;
        r.field.path = (sDir / "jet.vdb").string();
        r.output.path = (sDir / out).string();
        r.input.type = "spots";
        r.input.distribution = "poisson";
        r.output.upsample = 1;
        r.input.spacing = 7;
        r.input.radii = {1.0};
        r.lic.length = 8;
        return r;
    }
    static std::map<std::string, openvdb::FloatGrid::Ptr> read(const std::string& out)
    {
        openvdb::io::File file((sDir / out).string());
        file.open();
        std::map<std::string, openvdb::FloatGrid::Ptr> grids;
        for (auto it = file.beginName(); it != file.endName(); ++it) {
            auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(it.gridName()));
            if (g) grids[it.gridName()] = g;
        }
        return grids;
    }
    /// Speed at an output voxel's world position, clamped to the field's active box as the bake
    /// samples scalars.
    static double speedAt(const openvdb::FloatGrid& out, const openvdb::Coord& ijk)
    {
        openvdb::Vec3d idx = sSpeed->worldToIndex(out.indexToWorld(ijk));
        const openvdb::CoordBBox bb = sSpeed->evalActiveVoxelBoundingBox();
        for (int a = 0; a < 3; ++a) idx[a] = std::clamp(idx[a], double(bb.min()[a]), double(bb.max()[a]));
        return openvdb::tools::BoxSampler::sample(sSpeed->tree(), idx);
    }
    /// ROI weight at an output voxel, from the speed at its world position.
    static float roiAt(const openvdb::FloatGrid& out, const openvdb::Coord& ijk)
    {
        return lic::roiWeight(speedAt(out, ijk), sRoi[0], sRoi[1]);
    }

    static inline openvdb::Vec3SGrid::Ptr sVelocity;
    static inline openvdb::FloatGrid::Ptr sSpeed;
    static inline std::array<double, 2> sRoi;
};

struct LineCounts
{
    std::size_t lit = 0, litOutside = 0, unhaloed = 0;
};

LineCounts countLines(const openvdb::FloatGrid& density, const openvdb::FloatGrid& halo,
                      const std::function<float(const openvdb::Coord&)>& roi)
{
    LineCounts c;
    auto hacc = halo.getConstAccessor();
    for (auto it = density.cbeginValueOn(); it; ++it) {
        if (*it <= 0.05f) continue;
        ++c.lit;
        if (roi(it.getCoord()) == 0.0f) ++c.litOutside;
        if (!(hacc.getValue(it.getCoord()) > 0.05f)) ++c.unhaloed;
    }
    return c;
}

} // namespace

TEST_F(HaloBake, PreRoiLetsLinesLeaveTheRegionPostCutsThemAndHalosEncloseLines)
{
    auto pre = spotRecipe("pre.vdb");
    pre.roi = vdbexport::RoiSpec{"speed", sRoi, "pre"};
    const auto summary = vdbexport::bake(pre);
    auto post = pre;
    post.output.path = (sDir / "post.vdb").string();
    post.roi->mode = "post";
    vdbexport::bake(post);

    const auto a = read("pre.vdb"), b = read("post.vdb");
    ASSERT_TRUE(a.count("density") && a.count("halo"));
    auto roi = [&](const openvdb::Coord& ijk) { return roiAt(*a.at("density"), ijk); };
    const LineCounts cPre = countLines(*a.at("density"), *a.at("halo"), roi);
    const LineCounts cPost = countLines(*b.at("density"), *b.at("halo"), roi);
    std::printf("ROI speed [%.3f, %.3f]: pre %zu line voxels, %zu outside; post %zu, %zu outside; spots %s\n",
                sRoi[0], sRoi[1], cPre.lit, cPre.litOutside, cPost.lit, cPost.litOutside,
                summary["spots"]["count"].dump().c_str());
    EXPECT_GT(cPre.lit, 500u);
    EXPECT_GT(cPre.litOutside, cPre.lit / 20) << "pre: lines follow the flow out of the region";
    EXPECT_EQ(cPost.litOutside, 0u) << "post: nothing outside the region";
    EXPECT_GT(cPost.lit, 200u);
    // Halo ⊇ line: every line voxel lies inside its halo.
    EXPECT_EQ(cPre.unhaloed, 0u);
    EXPECT_EQ(cPost.unhaloed, 0u);
    // Halo is never below the line, and it is wider.
    EXPECT_GT(a.at("halo")->activeVoxelCount(), 0u);
    std::size_t haloLit = 0;
    for (auto it = a.at("halo")->cbeginValueOn(); it; ++it) haloLit += *it > 0.05f;
    EXPECT_GT(haloLit, 3 * cPre.lit / 2);
}

TEST_F(HaloBake, WidthSeriesIsMonotonicAndTheCompositeFollowsTheScalar)
{
    auto r = spotRecipe("width.vdb");
    r.input.radii = {0.75, 1.25, 2.0};
    r.width = vdbexport::WidthSpec{"speed", sRoi, true}; // slow flow = wide lines
    r.output.grids.setKey("write_series", true);
    vdbexport::bake(r);
    const auto g = read("width.vdb");
    for (const char* name : {"density", "halo", "density_w1", "density_w2", "density_w3", "halo_w1", "halo_w2", "halo_w3"})
        ASSERT_TRUE(g.count(name)) << name;
    auto lit = [&](const std::string& name) {
        std::size_t n = 0;
        for (auto it = g.at(name)->cbeginValueOn(); it; ++it) n += *it > 0.05f;
        return n;
    };
    const std::size_t w1 = lit("density_w1"), w2 = lit("density_w2"), w3 = lit("density_w3");
    std::printf("lit voxels per level: %zu %zu %zu; halos %zu %zu %zu\n", w1, w2, w3, lit("halo_w1"), lit("halo_w2"),
                lit("halo_w3"));
    EXPECT_LT(w1, w2);
    EXPECT_LT(w2, w3);
    EXPECT_LT(lit("halo_w1"), lit("halo_w3"));
    // Where speed ≤ lo the composite is the widest level, where speed ≥ hi the narrowest, and in
    // between it lies between its two neighbouring levels.
    auto d = g.at("density")->getConstAccessor();
    auto l1 = g.at("density_w1")->getConstAccessor(), l2 = g.at("density_w2")->getConstAccessor(),
         l3 = g.at("density_w3")->getConstAccessor();
    std::size_t slow = 0, fast = 0, between = 0;
    for (auto it = g.at("density")->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        const double s = speedAt(*g.at("density"), c);
        const float v = d.getValue(c);
        if (s <= sRoi[0] - 1e-3) {
            ASSERT_NEAR(v, l3.getValue(c), 1e-6);
            ++slow;
        } else if (s >= sRoi[1] + 1e-3) {
            ASSERT_NEAR(v, l1.getValue(c), 1e-6);
            ++fast;
        } else {
            const float lo = std::min({l1.getValue(c), l2.getValue(c), l3.getValue(c)});
            const float hi = std::max({l1.getValue(c), l2.getValue(c), l3.getValue(c)});
            ASSERT_GE(v, lo - 1e-6f);
            ASSERT_LE(v, hi + 1e-6f);
            ++between;
        }
    }
    EXPECT_GT(slow, 100u);
    EXPECT_GT(between, 100u);
}

TEST_F(HaloBake, SparseOutputIsMuchSmallerThanTheDenseBake)
{
    auto r = spotRecipe("sparse.vdb");
    r.input.spacing = 10;
    const auto s = vdbexport::bake(r);
    vdbexport::Recipe noise;
    noise.field.path = r.field.path;
    noise.output.path = (sDir / "dense.vdb").string();
    noise.lic.length = 8;
    noise.output.upsample = 1;
    const auto n = vdbexport::bake(noise);
    const auto sparseVoxels = s["density_active_voxels"].get<std::uint64_t>();
    const auto denseVoxels = n["density_active_voxels"].get<std::uint64_t>();
    const auto sparseBytes = fs::file_size(sDir / "sparse.vdb"), denseBytes = fs::file_size(sDir / "dense.vdb");
    std::printf("sparse spots: %llu active voxels, %llu bytes; dense noise: %llu voxels, %llu bytes\n",
                (unsigned long long)sparseVoxels, (unsigned long long)sparseBytes, (unsigned long long)denseVoxels,
                (unsigned long long)denseBytes);
    EXPECT_EQ(denseVoxels, n["output_voxels"].get<std::uint64_t>());
    EXPECT_LT(sparseVoxels, denseVoxels / 2);
    EXPECT_LT(sparseBytes, denseBytes); // even with two grids (density and halo)
    // All grids of a spot bake share the sparse topology.
    const auto g = read("sparse.vdb");
    EXPECT_TRUE(g.at("halo")->tree().hasSameTopology(g.at("density")->tree()));
}

TEST_F(HaloBake, SpotBakesAreBitIdenticalForAnyThreadCount)
{
    auto r = spotRecipe("t1.vdb");
    r.input.radii = {1.0, 1.5};
    r.width = vdbexport::WidthSpec{"speed", std::nullopt, false};
    r.threads = 1;
    vdbexport::bake(r);
    r.output.path = (sDir / "t2.vdb").string();
    r.threads = 2;
    vdbexport::bake(r);
    const auto a = read("t1.vdb"), b = read("t2.vdb");
    for (const char* name : {"density", "halo"}) {
        ASSERT_TRUE(a.at(name)->tree().hasSameTopology(b.at(name)->tree())) << name;
        auto bacc = b.at(name)->getConstAccessor();
        for (auto it = a.at(name)->cbeginValueOn(); it; ++it)
            ASSERT_EQ(*it, bacc.getValue(it.getCoord())) << name << " " << it.getCoord();
    }
}

TEST_F(HaloBake, CyclicSpotLoopWritesHalosInEveryFrame)
{
    auto r = spotRecipe("loop.vdb");
    r.animation.frames = 3;
    vdbexport::bake(r);
    openvdb::Index64 active = 0;
    for (int f = 1; f <= 3; ++f) {
        const auto g = read(fs::path(vdbexport::framePath("loop.vdb", f, 3)).string());
        ASSERT_TRUE(g.count("density") && g.count("halo"));
        if (f == 1) active = g.at("density")->activeVoxelCount();
        EXPECT_EQ(g.at("density")->activeVoxelCount(), active); // one topology for the loop
    }
}

TEST_F(HaloBake, RecipeCombinationsThatMeanNothingAreRefused)
{
    auto r = spotRecipe("bad.vdb");
    r.input.radii = {1.0, 2.0};
    EXPECT_THROW(vdbexport::bake(r), lic::InputError); // levels nobody uses
    r.input.radii = {1, 2, 3, 4, 5};
    r.output.grids.setKey("write_series", true);
    EXPECT_THROW(vdbexport::bake(r), lic::InputError);
    auto n = spotRecipe("bad.vdb");
    n.input.type = "noise";
    n.width = vdbexport::WidthSpec{"speed", std::nullopt, false};
    EXPECT_THROW(vdbexport::bake(n), lic::InputError);
    auto s = spotRecipe("bad.vdb");
    s.input.surface = vdbexport::SurfaceSpec{"speed", 1e9};
    EXPECT_THROW(vdbexport::bake(s), lic::InputError); // no ridge that high
    EXPECT_FALSE(fs::exists(sDir / "bad.vdb"));
}

using SurfaceBake = lictest::TempDirTest;

TEST_F(SurfaceBake, SpotsOnTheRidgeOfSpeedGradientShowTheShearLayer)
{
    // Shear layer: u = 1.5 + tanh((z − 15.5)/2.5) along x; |∇speed| peaks on the plane z = 15.5.
    const fs::path& dir = mDir;
    auto grid = lictest::makeField(openvdb::Coord(32), 1.0, openvdb::Vec3d(0.0), [](const openvdb::Vec3d& p) {
        return openvdb::Vec3d(1.5 + std::tanh((p[2] - 15.5) / 2.5), 0.0, 0.1 * std::sin(p[0] / 5.0));
    });
    vdbexport::writeVdbAtomic((dir / "shear.vdb").string(), {grid});
    vdbexport::Recipe r;
    r.field.path = (dir / "shear.vdb").string();
    r.output.path = (dir / "surface.vdb").string();
    r.input.type = "spots";
    r.input.spacing = 6;
    r.input.radii = {1.0};
    r.input.surface = vdbexport::SurfaceSpec{"speed-gradient", 0.2};
    r.lic.length = 6;
    const auto summary = vdbexport::bake(r);
    const auto spots = summary["spots"]["count"].get<std::size_t>();
    EXPECT_GT(spots, 50u);
    openvdb::io::File file(r.output.path);
    file.open();
    auto density = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("density"));
    std::size_t lit = 0, offSurface = 0;
    for (auto it = density->cbeginValueOn(); it; ++it) {
        if (*it <= 0.05f) continue;
        ++lit;
        const double z = density->indexToWorld(it.getCoord())[2];
        if (std::abs(z - 15.5) > 2.5) ++offSurface; // radius + edge + the flow's small z wiggle
    }
    std::printf("surface spots %zu, line voxels %zu, off the surface %zu\n", spots, lit, offSurface);
    EXPECT_GT(lit, 1000u);
    EXPECT_EQ(offSurface, 0u);
}

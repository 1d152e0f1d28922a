// Distributed bakes without MPI: the brick assignment (deterministic, contiguous, balanced by
// active voxels), a rank's part of the field (read clipped from a .vdb: the same domain, bricks,
// bounds and speed threshold as the whole field, and every brick of the share convolved to the
// same bits as from the whole field, for noise and spots, sparse and staggered fields), and the
// one-process Job (every collective a no-op, exceptions unchanged). The MPI runs themselves are
// in tests/cli/test_mpi.cpp.
#include "vdbexport/bake/Recipe.h"
#include "vdbexport/io/AtomicWrite.h"

#include "bake/Distribute.h"
#include "bake/FieldShare.h"
#include "bake/Plan.h"

#include "TempDirSuite.h"

#include "lic/engine/Engine.h"
#include "lic/util/Error.h"
#include "lic/field/Presets.h"
#include "lic/texture/Noise.h"
#include "lic/texture/Spots.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstring>
#include <limits>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>

namespace fs = std::filesystem;
using namespace vdbexport;

namespace {

class Distribute : public lictest::TempDirSuite<Distribute>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("distribute");
        // Dense, with a float grid the bake can colour by.
        lictest::writePresetField(sDir / "jet.vdb", "tabbed-jet", openvdb::Coord(20, 20, 28));
        // Sparse: a hole of inactive voxels and a ragged edge, so a part's own active box is not
        // the whole field's on any face; and a staggered copy of it.
        const lic::PresetField abc = lic::makePresetField("abc", openvdb::Coord(24));
        auto sparse = abc.velocity->deepCopy();
        sparse->setName("velocity");
        for (auto it = sparse->tree().beginValueOn(); it; ++it) {
            const openvdb::Coord c = it.getCoord();
            const bool hole = (c - openvdb::Coord(12, 12, 12)).asVec3d().length() < 5.0;
            const bool ragged = c[0] > 20 && c[1] < 6;
            if (hole || ragged) it.setValueOff();
        }
        writeVdbAtomic((sDir / "sparse.vdb").string(), {sparse});
        auto staggered = sparse->deepCopy();
        staggered->setGridClass(openvdb::GRID_STAGGERED);
        writeVdbAtomic((sDir / "staggered.vdb").string(), {staggered});
    }

    static Recipe recipe(const std::string& field)
    {
        Recipe r;
        r.field.path = (sDir / field).string();
        r.output.path = (sDir / "out.vdb").string();
        r.lic.length = 6;
        r.lic.brick = 16; // many bricks: 40³–48³ outputs
        r.lic.engine = "fast"; // what bake() resolves "auto" to for noise
        return r;
    }
};

/// Every brick's channels, keyed by brick id.
template<typename Convolve>
std::map<std::size_t, std::vector<float>> collect(Convolve&& convolve)
{
    std::map<std::size_t, std::vector<float>> out;
    std::mutex m;
    convolve([&](const lic::BrickChannels& b) {
        const std::size_t n = b.brick->blocks.size() * std::size_t(b.channels) * lic::OutputDomain::kBlockVoxels;
        const std::lock_guard lock(m);
        out[b.index].assign(b.values, b.values + n);
    });
    return out;
}

bool sameBits(const std::vector<float>& a, const std::vector<float>& b)
{
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

} // namespace

TEST_F(Distribute, AssignmentIsContiguousBalancedAndDeterministic)
{
    const Recipe r = recipe("jet.vdb");
    const pipeline::Plan plan = pipeline::makePlan(r);
    const pipeline::FieldShare whole = pipeline::readFieldShare(plan, 0, 1);
    const lic::BrickLayout& layout = *whole.layout;
    ASSERT_GE(layout.size(), 30u);
    std::uint64_t biggest = 0, total = 0;
    for (const lic::Brick& b : layout.bricks()) {
        biggest = std::max(biggest, b.activeVoxels);
        total += b.activeVoxels;
    }
    for (int ranks : {1, 2, 3, 4, 7, 64, 200}) {
        const std::vector<int> a = pipeline::assignBricks(layout, ranks);
        EXPECT_EQ(a, pipeline::assignBricks(layout, ranks)) << "deterministic";
        // Every process works the assignment out alone, from the layout of its own share of the
        // field: the last rank's share, read on one thread, gives the same assignment.
        if (ranks <= 7) {
            const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
            const pipeline::FieldShare last = pipeline::readFieldShare(plan, ranks - 1, ranks);
            EXPECT_EQ(last.assignment, a) << "rank " << ranks - 1 << " of " << ranks;
        }
        ASSERT_EQ(a.size(), layout.size());
        std::vector<std::uint64_t> load(std::size_t(ranks), 0);
        for (std::size_t id = 0; id < a.size(); ++id) {
            ASSERT_GE(a[id], 0);
            ASSERT_LT(a[id], ranks);
            load[std::size_t(a[id])] += layout[id].activeVoxels;
        }
        // Every share within one brick of the ideal T/N (as long as there are bricks to share).
        const double ideal = double(total) / ranks;
        for (int rank = 0; rank < ranks && std::size_t(ranks) <= layout.size(); ++rank)
            EXPECT_LE(std::abs(double(load[std::size_t(rank)]) - ideal), double(biggest)) << ranks << " ranks, rank " << rank;
        // Contiguous runs: along the Morton order the ranks never go back.
        const std::vector<std::size_t> order = pipeline::mortonOrder(layout);
        ASSERT_EQ(order.size(), layout.size());
        for (std::size_t i = 1; i < order.size(); ++i) ASSERT_LE(a[order[i - 1]], a[order[i]]) << ranks << " ranks";
        if (std::size_t(ranks) <= layout.size()) { // every rank gets work
            EXPECT_EQ(std::set<int>(a.begin(), a.end()).size(), std::size_t(ranks)) << ranks << " ranks";
        }
        // Every brick in exactly one share.
        std::size_t all = 0;
        for (int rank = 0; rank < ranks; ++rank) all += pipeline::bricksOf(a, rank).size();
        EXPECT_EQ(all, layout.size());
    }
}

TEST_F(Distribute, APartOfTheFieldConvolvesItsBricksLikeTheWholeField)
{
    for (const std::string file : {"jet.vdb", "sparse.vdb", "staggered.vdb"}) {
        for (const bool spots : {false, true}) {
            Recipe r = recipe(file);
            if (spots) {
                r.input.type = "spots";
                r.input.spacing = 5;
                r.input.radii = {1.0, 2.0};
                r.output.grids.setKey("write_series", true);
            }
            const pipeline::Plan plan = pipeline::makePlan(r);
            const pipeline::FieldShare whole = pipeline::readFieldShare(plan, 0, 1);
            ASSERT_FALSE(whole.partial);
            const lic::OutputDomain& domain = *whole.domain;
            lic::SpotSet spotSet;
            if (spots) {
                const openvdb::CoordBBox ib = domain.indexBBox();
                for (const auto& c : lic::placeSpots({lic::SpotDistribution::Poisson, 5.0, 0.25, 3},
                                                     openvdb::BBoxd(ib.min().asVec3d() - 0.5, ib.max().asVec3d() + 0.5))) {
                    if (domain.slotOf(lic::OutputDomain::nearestVoxel(c)) < 0) continue;
                    spotSet.centers.push_back(c);
                    spotSet.weights.push_back(1.0f);
                }
            }
            auto convolve = [&](const lic::VelocityField& f, const lic::OutputDomain& d, const lic::BrickLayout& l) {
                return collect([&](const lic::BrickSink& sink) {
                    if (spots) {
                        lic::convolveSpotBricks({f, d, l, plan.settings, lic::nullProgress()},
                                                {spotSet, r.input.radii, r.input.haloScale}, sink);
                    } else {
                        lic::NoiseBrickSource noise(7, lic::NoiseFilter::Binomial, lic::ghostMargin(plan.settings));
                        lic::convolveNoiseBricks({f, d, l, plan.settings, lic::nullProgress()}, noise, sink);
                    }
                });
            };
            for (int ranks : {2, 5}) {
                for (int rank = 0; rank < ranks; ++rank) {
                    const std::string what = file + (spots ? " spots" : " noise") + ", rank " + std::to_string(rank) +
                                             " of " + std::to_string(ranks);
                    pipeline::FieldShare part = pipeline::readFieldShare(plan, rank, ranks);
                    ASSERT_TRUE(part.partial) << what << ": " << part.wholeReason;
                    ASSERT_TRUE(part.wholeReason.empty());
                    pipeline::makeField(part, whole.field->maxSpeed());
                    // The whole bake's domain, bricks and bounds, from the topology alone.
                    ASSERT_EQ(part.domain->blockCount(), domain.blockCount()) << what;
                    for (std::size_t b = 0; b < domain.blockCount(); ++b) {
                        ASSERT_EQ(part.domain->blockOrigin(b), domain.blockOrigin(b)) << what;
                        ASSERT_EQ(part.domain->blockMask(b), domain.blockMask(b)) << what;
                    }
                    ASSERT_EQ(part.layout->size(), whole.layout->size()) << what;
                    EXPECT_EQ(part.field->indexBBox(), whole.field->indexBBox()) << what;
                    EXPECT_EQ(part.field->activeVoxelCount(), whole.field->activeVoxelCount()) << what;
                    EXPECT_EQ(part.field->maxSpeed(), whole.field->maxSpeed()) << what;
                    EXPECT_EQ(part.field->isStaggered(), whole.field->isStaggered()) << what;
                    EXPECT_EQ(part.mine, pipeline::bricksOf(pipeline::assignBricks(*whole.layout, ranks), rank)) << what;
                    EXPECT_LE(part.voxelsHeld, whole.voxelsHeld) << what;
                    // Every brick of the share, bit for bit.
                    const auto a = convolve(*whole.field, domain, whole.layout->subset(part.mine));
                    const auto b = convolve(*part.field, *part.domain, part.layout->subset(part.mine));
                    ASSERT_EQ(a.size(), part.mine.size()) << what;
                    ASSERT_EQ(b.size(), a.size()) << what;
                    for (const auto& [id, values] : a) EXPECT_TRUE(sameBits(values, b.at(id))) << what << ", brick " << id;
                }
            }
        }
    }
}

TEST_F(Distribute, ARankHoldsOnlyItsPartOfALongField)
{
    // 96×16×16 field voxels: 4 ranks get about a quarter of x each, plus the margin.
    lictest::writePresetField(sDir / "long.vdb", "abc", openvdb::Coord(96, 16, 16), lictest::PresetGrids::Velocity);
    const Recipe r = recipe("long.vdb"); // the plan refers to it
    const pipeline::Plan plan = pipeline::makePlan(r);
    const pipeline::FieldShare whole = pipeline::readFieldShare(plan, 0, 1);
    const int m = pipeline::fieldMargin(plan, 2, lic::detail::integrationStride(*whole.domain, plan.settings));
    EXPECT_GE(m, 8);
    std::uint64_t held = 0;
    for (int rank = 0; rank < 4; ++rank) {
        pipeline::FieldShare part = pipeline::readFieldShare(plan, rank, 4);
        ASSERT_TRUE(part.partial);
        pipeline::makeField(part, whole.field->maxSpeed());
        // Its bricks' x-extent (a quarter of 96 voxels, to a brick) plus the margin on each side.
        EXPECT_LE(part.voxelsHeld, std::uint64_t(24 + 8 + 2 * m) * 16 * 16) << "rank " << rank;
        EXPECT_LT(part.voxelsHeld, whole.voxelsHeld) << "rank " << rank;
        held += part.voxelsHeld;
        // File scalars and velocity clipped alike: nothing outside the part is active.
        openvdb::CoordBBox box = part.loaded.velocity->evalActiveVoxelBoundingBox();
        EXPECT_TRUE(part.extent.region.isInside(box)) << "rank " << rank;
    }
    EXPECT_LT(held, 3 * whole.voxelsHeld); // four parts together: well under four wholes
}

TEST_F(Distribute, FieldsThatNeedTheWholeFileAreReadWhole)
{
    Recipe r = recipe("jet.vdb");
    r.field.mask = "zero";
    const pipeline::Plan plan = pipeline::makePlan(r);
    const pipeline::FieldShare s = pipeline::readFieldShare(plan, 1, 3);
    EXPECT_FALSE(s.partial);
    EXPECT_NE(s.wholeReason.find("mask"), std::string::npos) << s.wholeReason;
    ASSERT_TRUE(s.field);
    EXPECT_EQ(s.mine, pipeline::bricksOf(pipeline::assignBricks(*s.layout, 3), 1));
}

TEST(DistributeJob, OneProcessJobPassesEverythingThrough)
{
    pipeline::Job& job = pipeline::Job::current();
    ASSERT_EQ(job.size(), 1);
    EXPECT_EQ(job.rank(), 0);
    EXPECT_FALSE(job.distributed());
    EXPECT_EQ(job.stage("reading the field", [] { return 42; }), 42);
    EXPECT_THROW(job.stage("reading the field", []() -> int { throw lic::InputError("bad"); }), lic::InputError);
    EXPECT_THROW(job.stage("convolving", [] { throw std::bad_alloc(); }), std::bad_alloc);
    EXPECT_EQ(job.maxAll(2.5, "x"), 2.5);
    EXPECT_EQ(job.sumAll(std::uint64_t(7), "x"), 7u);
    EXPECT_EQ(job.allGather("abc", "x"), std::vector<std::string>{"abc"});
    EXPECT_FALSE(job.failed());
}

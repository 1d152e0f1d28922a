// Distributed bakes end to end: `mpirun --oversubscribe -np N licvdb bake …` (LICVDB_MPIEXEC)
// against the same bake in one process, grid by grid and bit for bit (noise with colour, region
// and every optional grid; spots with halos, three widths and colour; a 4-frame loop; 1 to 4
// ranks, 1 or 2 threads each), the summary's counters and the manifest; a rank's part of the
// field smaller than the whole; and faults: an error on one rank (bad input, out of memory, a
// NaN only one rank reads), a killed rank (while convolving, and while rank 0 writes a loop),
// a failing write on rank 0 — each ends the job with one clear message, a non-zero exit code and
// no file, temporary or not; a corrupt .vdb refused on every rank by the read checks. Splat and
// gather spots from parts of a long field. Unsteady sequences (8 frames of a moving tornado, noise
// and spots) identical to one process in every frame, a rank killed mid-sequence and a failed
// write leaving nothing. Fields are small (48×48×72 and 80³ outputs in 16³ bricks).
#include <gtest/gtest.h>

#include "CliRun.h"
#include "../unit/ManifestDigests.h"
#include "../unit/TempDirSuite.h"
#include "vdbexport/io/AtomicWrite.h"
#include "vdbexport/io/VdbCheck.h"

#include "lic/field/Presets.h"

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
using nlohmann::json;
using cli_test::RunResult;

namespace {

class MpiBake : public lictest::TempDirSuite<MpiBake>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("mpi", "logs");
        const lic::PresetField jet = lictest::writePresetField(sDir / "jet.vdb", "tabbed-jet", openvdb::Coord(24, 24, 36));
        // The same field with one NaN in a corner: only the ranks whose part holds it see it.
        auto nan = openvdb::gridPtrCast<openvdb::Vec3SGrid>(jet.velocity->deepCopyGrid());
        nan->tree().setValueOn(nan->evalActiveVoxelBoundingBox().max(), openvdb::Vec3s(std::nanf(""), 0.0f, 0.0f));
        vdbexport::writeVdbAtomic((sDir / "nan.vdb").string(), {nan});
        // A long field, so that a rank's part (its bricks ± the margin) is less than the whole.
        const lic::PresetField abc =
            lictest::writePresetField(sDir / "long.vdb", "abc", openvdb::Coord(16, 16, 96), lictest::PresetGrids::Velocity);
        // A moving field: 8 frames of the tornado (frame n at time n/24).
        for (int n = 1; n <= 8; ++n)
            lictest::writePresetField(sDir / ("t_000" + std::to_string(n) + ".vdb"), "tornado", openvdb::Coord(40),
                                      lictest::PresetGrids::Velocity, double(n) / 24.0);
        // A long sequence (the steady abc flow still carries the noise), for parts of each frame.
        for (int n = 1; n <= 6; ++n)
            vdbexport::writeVdbAtomic((sDir / ("l_000" + std::to_string(n) + ".vdb")).string(), {abc.velocity});
    }
    void SetUp() override { mOut = testDir(); }

    /// `licvdb bake ARGS --out NAME` in one process (`ranks` = 0) or under mpirun.
    RunResult bake(int ranks, const std::string& out, std::vector<std::string> args, const std::string& env = "")
    {
        args.insert(args.begin(), "bake");
        args.push_back("--out");
        args.push_back(out);
        std::string cmd = cli_test::licvdbCommand(args);
        if (ranks > 0) {
            cmd = cli_test::shellQuote(LICVDB_MPIEXEC) + " --allow-run-as-root --oversubscribe -np " + std::to_string(ranks) +
                  (env.empty() ? "" : " -x " + env.substr(0, env.find('='))) + " " + cmd;
        }
        if (!env.empty()) cmd = "env " + cli_test::shellQuote(env) + " " + cmd;
        return cli_test::runShell(mOut, sDir / "logs", cmd);
    }

    /// The same bake as one process (into `one`) and over 3 ranks (into `three`); both must succeed.
    void bakeOneAndThree(const std::vector<std::string>& args, RunResult& r1, RunResult& r3,
                         const std::string& one = "one.vdb", const std::string& three = "three.vdb")
    {
        r1 = bake(0, one, args);
        ASSERT_EQ(r1.code, 0) << r1.describe();
        r3 = bake(3, three, args);
        ASSERT_EQ(r3.code, 0) << r3.describe();
    }
    std::string field(const std::string& name = "jet.vdb") const { return (sDir / name).string(); }

    /// Names of the files in this test's directory.
    std::set<std::string> files() const
    {
        std::set<std::string> names;
        for (const auto& e : fs::directory_iterator(mOut)) names.insert(e.path().filename().string());
        return names;
    }

    /// The job failed with exit `code`, stderr holds `text`, and nothing is left behind.
    void expectCleanFailure(const RunResult& r, int code, const std::string& text) const
    {
        EXPECT_EQ(r.code, code) << r.describe();
        EXPECT_NE(r.err.find(text), std::string::npos) << r.describe();
        const std::set<std::string> left = files();
        EXPECT_TRUE(left.empty()) << "left behind: " << (left.empty() ? "" : *left.begin()) << "\n" << r.describe();
    }

    fs::path mOut;
};

openvdb::GridPtrVec readAll(const fs::path& path)
{
    openvdb::io::File file(path.string());
    file.open();
    openvdb::GridPtrVec grids;
    for (auto it = file.beginName(); it != file.endName(); ++it) grids.push_back(file.readGrid(it.gridName()));
    return grids;
}

/// Same topology and the same bits in every active voxel; the grid's own metadata equal except
/// what OpenVDB adds on writing.
template<typename GridT>
std::string compareGrid(const openvdb::GridBase& a, const openvdb::GridBase& b)
{
    const auto& ga = static_cast<const GridT&>(a);
    const auto& gb = static_cast<const GridT&>(b);
    if (!ga.tree().hasSameTopology(gb.tree())) return "topology differs";
    auto acc = gb.getConstAccessor();
    std::size_t differ = 0;
    for (auto it = ga.cbeginValueOn(); it; ++it) {
        const auto va = *it, vb = acc.getValue(it.getCoord());
        if (std::memcmp(&va, &vb, sizeof va) != 0) ++differ;
    }
    if (differ) return std::to_string(differ) + " voxels differ";
    for (auto m = a.beginMeta(); m != a.endMeta(); ++m) {
        if (m->first.rfind("file_", 0) == 0 || m->first == "licvdb_recipe") continue; // the recipe names the output
        const auto other = b[m->first];
        if (!other || other->str() != m->second->str()) return "metadata " + m->first + " differs";
    }
    return "";
}

/// Every grid of two bakes' files: names, order, bits.
void expectSameFiles(const fs::path& a, const fs::path& b, const std::string& what)
{
    const openvdb::GridPtrVec ga = readAll(a), gb = readAll(b);
    ASSERT_EQ(ga.size(), gb.size()) << what;
    ASSERT_GE(ga.size(), 1u) << what;
    for (std::size_t i = 0; i < ga.size(); ++i) {
        ASSERT_EQ(ga[i]->getName(), gb[i]->getName()) << what;
        const std::string diff = ga[i]->isType<openvdb::FloatGrid>() ? compareGrid<openvdb::FloatGrid>(*ga[i], *gb[i])
                                                                    : compareGrid<openvdb::Vec3SGrid>(*ga[i], *gb[i]);
        EXPECT_EQ(diff, "") << what << ": grid " << ga[i]->getName();
        EXPECT_GT(ga[i]->activeVoxelCount(), 1000u) << what << ": grid " << ga[i]->getName();
    }
}

/// expectSameFiles for every frame of two loops `dir/a_0001.vdb` … and `dir/b_0001.vdb` ….
void expectSameFrames(const fs::path& dir, const std::string& a, const std::string& b, int frames, const std::string& what)
{
    for (int f = 1; f <= frames; ++f) {
        const std::string suffix = "_000" + std::to_string(f) + ".vdb";
        expectSameFiles(dir / (a + suffix), dir / (b + suffix), what + " frame " + std::to_string(f));
    }
}

/// The parts of a summary that must not depend on the rank count. The splat engine traces each
/// spot on every rank its footprint reaches, so its streamlines and samples summed over the ranks
/// count those spots once per rank (the distribution's extra work): left out for splat.
json counters(const json& s)
{
    const bool splat = s["engine"] == "splat";
    return {s["output_voxels"], splat ? json() : s["streamlines"], splat ? json() : s["samples"], s["deposits"],
            s["bricks"], s["brick_size"], s["spots"], s["raw_mean"], s["raw_stddev"], s["density_active_voxels"],
            s["field"]["active_voxels"], s["field"]["world_bbox"], s["frames"], s["engine"]};
}

/// A manifest without the names that differ by the output path.
json manifestCore(const fs::path& p)
{
    json m = json::parse(cli_test::readText(p));
    m["recipe"]["output"].erase("path");
    m["recipe"].erase("threads"); // threads per rank may differ between the runs compared
    m.erase("files");
    m.erase("sha256"); // of files whose recipe metadata names their own path
    return m;
}

const std::vector<std::string> kNoise = {"--field", "", "--brick", "16", "--length", "8", "--color", "vorticity",
                                         "--write-tangent", "--write-input", "--roi", "speed", "--roi-range", "0.3,5",
                                         "--quiet", "--json"};

/// An unsteady sequence over the 8 tornado frames (`input`: noise or spots).
std::vector<std::string> sequenceArgs(const fs::path& dir, const std::string& input)
{
    std::vector<std::string> a = {"--field", (dir / "t_####.vdb").string(), "--field-frames", "1,8", "--input", input,
                                  "--brick", "16", "--length", "8", "--quiet", "--json"};
    if (input == "spots") a.insert(a.end(), {"--spacing", "6", "--halo-scale", "2.5", "--color", "speed"});
    else a.insert(a.end(), {"--color", "vorticity", "--write-input"});
    return a;
}

std::vector<std::string> withField(std::vector<std::string> args, const std::string& field)
{
    args[1] = field;
    return args;
}

} // namespace

TEST_F(MpiBake, NoiseIsBitIdenticalToOneProcessForOneToFourRanks)
{
    const auto args = withField(kNoise, field());
    auto one = args;
    one.insert(one.end(), {"--threads", "1"});
    const RunResult r1 = bake(0, "one.vdb", one);
    ASSERT_EQ(r1.code, 0) << r1.describe();
    const json s1 = json::parse(r1.out);
    ASSERT_GE(s1["bricks"].get<int>(), 30);
    for (const auto& [ranks, threads] : std::vector<std::pair<int, int>>{{3, 1}, {1, 1}, {2, 2}, {4, 1}}) {
        const std::string name = "np" + std::to_string(ranks) + "_t" + std::to_string(threads) + ".vdb";
        auto a = args;
        a.insert(a.end(), {"--threads", std::to_string(threads)});
        const RunResult r = bake(ranks, name, a);
        ASSERT_EQ(r.code, 0) << r.describe();
        const json s = json::parse(r.out); // one summary: rank 0 alone prints
        expectSameFiles(mOut / "one.vdb", mOut / name, name);
        EXPECT_EQ(counters(s), counters(s1)) << name;
        EXPECT_EQ(manifestCore(mOut / ("np" + std::to_string(ranks) + "_t" + std::to_string(threads) + ".licvdb.json")),
                  manifestCore(mOut / "one.licvdb.json"))
            << name;
        if (ranks > 1) {
            ASSERT_EQ(s["ranks"].size(), std::size_t(ranks)) << r.out;
            EXPECT_TRUE(s["mpi"]["partial_read"].get<bool>()) << r.out;
            std::uint64_t bricks = 0, least = ~std::uint64_t(0);
            for (const json& rank : s["ranks"]) {
                bricks += rank["bricks"].get<std::uint64_t>();
                least = std::min(least, rank["field_voxels_held"].get<std::uint64_t>());
                EXPECT_GT(rank["seconds"]["convolve"].get<double>(), 0.0);
            }
            EXPECT_EQ(bricks, s1["bricks"].get<std::uint64_t>());
            EXPECT_LE(least, 24u * 24u * 36u) << r.out; // the whole field here: see the long field below
        }
    }
}

TEST_F(MpiBake, EachRankReadsOnlyItsPartOfALongField)
{
    const std::vector<std::string> args = {"--field", field("long.vdb"), "--brick", "16", "--length", "8",
                                           "--color", "q-criterion", "--quiet", "--json"};
    const RunResult r1 = bake(0, "one.vdb", args);
    ASSERT_EQ(r1.code, 0) << r1.describe();
    const RunResult r4 = bake(4, "four.vdb", args);
    ASSERT_EQ(r4.code, 0) << r4.describe();
    expectSameFiles(mOut / "one.vdb", mOut / "four.vdb", "long field");
    const json s = json::parse(r4.out);
    ASSERT_TRUE(s["mpi"]["partial_read"].get<bool>()) << r4.out;
    std::uint64_t held = 0;
    const std::uint64_t whole = 16u * 16u * 96u;
    for (const json& rank : s["ranks"]) {
        EXPECT_LT(rank["field_voxels_held"].get<std::uint64_t>(), whole) << r4.out;
        held += rank["field_voxels_held"].get<std::uint64_t>();
    }
    EXPECT_LT(held, 3 * whole) << "four parts hold less than three whole fields\n" << r4.out;
}

TEST_F(MpiBake, SplatSpotsOnALongFieldAreIdenticalFromPartsOfIt)
{
    // Splat (the default for spots) traces every spot within reach of a rank's bricks over its
    // whole support: the widest margin; the gather engine (fast) for spots too.
    for (const std::string engine : {"splat", "fast"}) {
        const std::vector<std::string> args = {"--field", field("long.vdb"), "--brick", "16", "--length", "6",
                                               "--input", "spots", "--spacing", "5", "--radii", "1,2",
                                               "--width", "speed", "--color", "vorticity", "--engine", engine,
                                               "--quiet", "--json"};
        RunResult r1, r3;
        ASSERT_NO_FATAL_FAILURE(bakeOneAndThree(args, r1, r3, engine + "1.vdb", engine + "3.vdb"));
        expectSameFiles(mOut / (engine + "1.vdb"), mOut / (engine + "3.vdb"), engine + " spots, long field");
        EXPECT_EQ(counters(json::parse(r3.out)), counters(json::parse(r1.out))) << engine;
        const json s = json::parse(r3.out);
        ASSERT_TRUE(s["mpi"]["partial_read"].get<bool>()) << r3.out;
        bool lessThanWhole = false;
        for (const json& rank : s["ranks"]) lessThanWhole |= rank["field_voxels_held"].get<std::uint64_t>() < 16u * 16u * 96u;
        EXPECT_TRUE(lessThanWhole) << engine << ": some rank holds less than the whole field\n" << r3.out;
    }
    // A comet loop's lines run a comet spacing further each way (splatSpotReach, and the fast
    // engine's field reach): every frame, and the velocity grid, the same from parts of the field.
    for (const std::string engine : {"splat", "fast"}) {
        const std::vector<std::string> loop = {"--field", field("long.vdb"), "--brick", "16", "--length", "6",
                                               "--input", "spots", "--spacing", "5", "--radii", "1",
                                               "--frames", "4", "--write-velocity", "--engine", engine,
                                               "--quiet", "--json"};
        RunResult r1, r3;
        ASSERT_NO_FATAL_FAILURE(bakeOneAndThree(loop, r1, r3, engine + "-comets1.vdb", engine + "-comets3.vdb"));
        expectSameFrames(mOut, engine + "-comets1", engine + "-comets3", 4, engine + " comet loop, long field");
        ASSERT_TRUE(json::parse(r3.out)["mpi"]["partial_read"].get<bool>()) << r3.out;
    }
}

TEST_F(MpiBake, AFourFrameLoopIsBitIdenticalInEveryFrame)
{
    auto args = withField(kNoise, field());
    args.insert(args.end(), {"--frames", "4"});
    RunResult r1, r3;
    ASSERT_NO_FATAL_FAILURE(bakeOneAndThree(args, r1, r3));
    EXPECT_EQ(counters(json::parse(r3.out)), counters(json::parse(r1.out)));
    expectSameFrames(mOut, "one", "three", 4, "noise loop");
    EXPECT_EQ(manifestCore(mOut / "three.licvdb.json"), manifestCore(mOut / "one.licvdb.json"));
    // manifestCore() leaves the digests out (the recipe in each file names its own path): every
    // frame's digest, as rank 0 wrote it, is checked against the file itself.
    lictest::expectManifestDigests(mOut / "three.licvdb.json", 4);
    lictest::expectManifestDigests(mOut / "one.licvdb.json", 4);
}

TEST_F(MpiBake, SpotsWithHalosWidthsAndColourAreBitIdentical)
{
    const std::vector<std::string> args = {"--field", field(), "--brick", "16", "--length", "8", "--input", "spots",
                                           "--spacing", "6", "--radii", "1,1.5,2", "--width", "speed", "--color",
                                           "temperature", "--colormap", "heated-object", "--write-series",
                                           "--write-tangent", "--quiet", "--json"};
    RunResult r1, r3;
    ASSERT_NO_FATAL_FAILURE(bakeOneAndThree(args, r1, r3));
    expectSameFiles(mOut / "one.vdb", mOut / "three.vdb", "spots");
    EXPECT_EQ(counters(json::parse(r3.out)), counters(json::parse(r1.out)));
    EXPECT_GT(json::parse(r1.out)["spots"]["count"].get<int>(), 100);
    EXPECT_EQ(manifestCore(mOut / "three.licvdb.json"), manifestCore(mOut / "one.licvdb.json"));
    // A spot loop too: every frame of line and halo.
    auto loop = args;
    loop.insert(loop.end(), {"--frames", "3"});
    ASSERT_EQ(bake(0, "loop1.vdb", loop).code, 0);
    const RunResult l3 = bake(3, "loop3.vdb", loop);
    ASSERT_EQ(l3.code, 0) << l3.describe();
    expectSameFrames(mOut, "loop1", "loop3", 3, "spot loop");
}

TEST_F(MpiBake, AFieldThatNeedsTheWholeFileIsReadWholeAndStillIdentical)
{
    auto args = withField(kNoise, field());
    args.insert(args.end(), {"--mask", "zero"});
    RunResult r1, r3;
    ASSERT_NO_FATAL_FAILURE(bakeOneAndThree(args, r1, r3));
    const json s = json::parse(r3.out);
    EXPECT_FALSE(s["mpi"]["partial_read"].get<bool>());
    EXPECT_NE(s["mpi"]["whole_read_reason"].get<std::string>().find("mask"), std::string::npos) << r3.out;
    expectSameFiles(mOut / "one.vdb", mOut / "three.vdb", "mask zero");
}

// ---- faults ---------------------------------------------------------------------------------

TEST_F(MpiBake, BadInputOnOneRankEndsTheJobWithExitTwoAndOneMessage)
{
    const RunResult r = bake(3, "out.vdb", withField(kNoise, field()), "LICVDB_TEST_FAULT=1:reading:input");
    expectCleanFailure(r, 2, "licvdb bake: error: rank 1 of 3 failed while reading the field: injected test fault");
    std::size_t n = 0;
    for (std::size_t at = r.err.find("licvdb bake: error"); at != std::string::npos; at = r.err.find("licvdb bake: error", at + 1)) ++n;
    EXPECT_EQ(n, 1u) << r.describe();
}

TEST_F(MpiBake, ANaNThatOnlyOneRankReadsFailsTheWholeJob)
{
    // The corner voxel lies in the last bricks' part only; every rank leaves with exit 2.
    const RunResult r = bake(3, "out.vdb", withField(kNoise, field("nan.vdb")));
    expectCleanFailure(r, 2, "NaN or infinite");
    EXPECT_NE(r.err.find("failed while reading the field"), std::string::npos) << r.describe();
}

TEST_F(MpiBake, OutOfMemoryOnOneRankEndsTheJobWithExitOne)
{
    const RunResult r = bake(3, "out.vdb", withField(kNoise, field()), "LICVDB_TEST_FAULT=2:convolving:oom");
    expectCleanFailure(r, 1, "rank 2 of 3 failed while convolving: out of memory");
}

TEST_F(MpiBake, AKilledRankEndsTheJob)
{
    const RunResult r = bake(3, "out.vdb", withField(kNoise, field()), "LICVDB_TEST_FAULT=1:convolving:kill");
    EXPECT_NE(r.code, 0) << r.describe();
    EXPECT_NE(r.err.find("signal 9"), std::string::npos) << r.describe(); // mpirun names the rank and signal
    EXPECT_TRUE(files().empty()) << r.describe();
}

TEST_F(MpiBake, ARankKilledWhileRankZeroWritesALoopLeavesNoFrame)
{
    auto args = withField(kNoise, field());
    args.insert(args.end(), {"--frames", "4"});
    // Rank 0 has written frames 1 and 2 when rank 1 dies composing frame 3.
    const RunResult r = bake(3, "out.vdb", args, "LICVDB_TEST_FAULT=1:composing frame 3:kill");
    EXPECT_NE(r.code, 0) << r.describe();
    EXPECT_TRUE(files().empty()) << "left behind: " << (files().empty() ? "" : *files().begin()) << "\n" << r.describe();
}

TEST_F(MpiBake, AWriteFailureOnRankZeroEndsEveryRank)
{
    auto args = withField(kNoise, field());
    args.insert(args.end(), {"--frames", "4"});
    const RunResult r = bake(3, "out.vdb", args, "LICVDB_TEST_FAULT=0:writing frame 2:error");
    expectCleanFailure(r, 1, "rank 0 of 3 failed while writing: injected test fault");
}

TEST_F(MpiBake, ACorruptVdbIsRefusedByTheSameChecksOnEveryRank)
{
    // The .vdb read defences (docs/inputs.md) run on every rank before its clipped read: a file
    // cut short is refused with exit 2 and one message, and nothing is written.
    const std::string bytes = cli_test::readText(sDir / "long.vdb");
    const fs::path cut = mOut.parent_path() / "cut.vdb";
    {
        std::ofstream out(cut, std::ios::binary);
        out.write(bytes.data(), std::streamsize(bytes.size() - 100));
    }
    const RunResult r = bake(2, "out.vdb", withField(kNoise, cut.string()));
    expectCleanFailure(r, 2, "expected an intact OpenVDB .vdb file");
    EXPECT_EQ(r.err.find("licvdb bake: error"), r.err.rfind("licvdb bake: error")) << r.describe();
    // Refused by the structural check (layer 1: its marker and rule, vdbexport/io/VdbCheck.h) on
    // both ranks, not by OpenVDB's reader, whose message ("cannot read …") also ends in "expected
    // an intact OpenVDB .vdb file".
    const std::string byTheCheck = "all 2 ranks failed while reading the field: " + std::string(vdbexport::kVdbCheckMarker)
                                 + "grid-end] '" + cut.string() + "' is truncated or corrupt";
    EXPECT_NE(r.err.find(byTheCheck), std::string::npos) << "expected \"" << byTheCheck << "\"\n" << r.describe();
}

TEST_F(MpiBake, AFieldMissingOnEveryRankIsOneMessage)
{
    const RunResult r = bake(3, "out.vdb", withField(kNoise, (sDir / "missing.vdb").string()));
    expectCleanFailure(r, 2, "missing.vdb");
    EXPECT_EQ(r.err.find("licvdb bake: error"), r.err.rfind("licvdb bake: error")) << r.describe();
}

TEST_F(MpiBake, AnUnsteadySequenceOfNoiseIsIdenticalToOneProcessInEveryFrame)
{
    // The carried noise is held in parts: each rank keeps the blocks its bricks read and receives
    // the previous frame's margin blocks from their owners.
    RunResult r1, r3;
    bakeOneAndThree(sequenceArgs(sDir, "noise"), r1, r3, "one.vdb", "three.vdb");
    expectSameFrames(mOut, "one", "three", 8, "noise sequence");
    const json s1 = json::parse(r1.out), s3 = json::parse(r3.out);
    ASSERT_EQ(s3["per_frame"].size(), 8u) << r3.out;
    for (std::size_t f = 0; f < 8; ++f) {
        EXPECT_EQ(s3["per_frame"][f]["texture"], s1["per_frame"][f]["texture"]) << "frame " << f + 1;
        EXPECT_EQ(s3["per_frame"][f]["raw_mean"], s1["per_frame"][f]["raw_mean"]) << "frame " << f + 1;
    }
    // The noise moved (frames 2–8 carry most voxels from the previous frame) ...
    EXPECT_GT(s1["per_frame"][4]["texture"]["carried"].get<double>(), 0.5 * s1["per_frame"][4]["texture"]["voxels"].get<double>());
    // ... each rank held a part of it, and the margins travelled.
    ASSERT_EQ(s3["ranks"].size(), 3u) << r3.out;
    const std::uint64_t blocks = s1["per_frame"][0]["output_voxels"].get<std::uint64_t>() / 512; // a full cube
    ASSERT_EQ(blocks, 1000u); // 80³ output voxels in 8³ blocks
    std::uint64_t received = 0;
    for (const json& rank : s3["ranks"]) {
        EXPECT_LT(rank["texture_blocks_held"].get<std::uint64_t>(), blocks) << r3.out;
        EXPECT_GT(rank["cpu_seconds"].get<double>(), 0.0) << r3.out;
        received += rank["texture_bytes_received"].get<std::uint64_t>();
    }
    EXPECT_GT(received, 0u) << r3.out;
    EXPECT_TRUE(s3["mpi"]["partial_read"].get<bool>()) << r3.out;
    EXPECT_EQ(manifestCore(mOut / "three.licvdb.json"), manifestCore(mOut / "one.licvdb.json"));
}

TEST_F(MpiBake, EachRankReadsOnlyItsPartOfEveryFrameOfANoiseSequence)
{
    // The part's margin grows by what the noise's advance reaches (its kept blocks' neighbours and
    // half a frame's displacement: ~10 voxels along z at 8 frames per second), and is still less
    // than the whole on a long field.
    const std::vector<std::string> args = {"--field", (sDir / "l_####.vdb").string(), "--field-frames", "1,6",
                                           "--fps", "8", "--upsample", "1", "--brick", "16", "--length", "8",
                                           "--quiet", "--json"};
    RunResult r1, r3;
    bakeOneAndThree(args, r1, r3, "one.vdb", "three.vdb");
    for (int f = 1; f <= 6; ++f) {
        const std::string suffix = "_000" + std::to_string(f) + ".vdb";
        expectSameFiles(mOut / ("one" + suffix), mOut / ("three" + suffix), "long sequence frame " + std::to_string(f));
    }
    const json s3 = json::parse(r3.out);
    EXPECT_TRUE(s3["mpi"]["partial_read"].get<bool>()) << r3.out;
    std::uint64_t least = ~std::uint64_t(0);
    for (const json& rank : s3["ranks"]) least = std::min(least, rank["field_voxels_held"].get<std::uint64_t>());
    EXPECT_LT(least, 16u * 16u * 96u) << r3.out;
    EXPECT_GT(json::parse(r1.out)["per_frame"][5]["texture"]["carried"].get<std::uint64_t>(), 0u) << r1.out;
}

TEST_F(MpiBake, AnUnsteadySequenceOfSpotsIsIdenticalToOneProcessInEveryFrame)
{
    RunResult r1, r3;
    bakeOneAndThree(sequenceArgs(sDir, "spots"), r1, r3, "one.vdb", "three.vdb");
    expectSameFrames(mOut, "one", "three", 8, "spot sequence");
    EXPECT_FALSE(json::parse(r3.out)["mpi"]["partial_read"].get<bool>()) << "the flock needs every frame whole";
    const json s1 = json::parse(r1.out), s3 = json::parse(r3.out);
    for (std::size_t f = 0; f < 8; ++f)
        EXPECT_EQ(s3["per_frame"][f]["texture"], s1["per_frame"][f]["texture"]) << "frame " << f + 1;
    EXPECT_GT(s1["per_frame"][7]["texture"]["born"].get<int>() + s1["per_frame"][7]["texture"]["left"].get<int>(), 0)
        << "the flock should change over the tornado's frames";
    EXPECT_EQ(manifestCore(mOut / "three.licvdb.json"), manifestCore(mOut / "one.licvdb.json"));
}

TEST_F(MpiBake, ARankKilledMidSequenceLeavesNoFrame)
{
    // Rank 0 has staged frames 1 … 4 when rank 1 dies composing frame 5.
    const RunResult r = bake(3, "seq.vdb", sequenceArgs(sDir, "noise"), "LICVDB_TEST_FAULT=1:composing frame 5:kill");
    EXPECT_NE(r.code, 0) << r.describe();
    EXPECT_TRUE(files().empty()) << "left behind: " << (files().empty() ? "" : *files().begin()) << "\n" << r.describe();
}

TEST_F(MpiBake, AFailureMidSequenceIsOneMessageAndNoFrame)
{
    // Rank 0 fails to stage frame 3 of a spot sequence: every rank leaves, frames 1 and 2 unseen.
    const RunResult r = bake(3, "seq.vdb", sequenceArgs(sDir, "spots"), "LICVDB_TEST_FAULT=0:writing frame 3:error");
    expectCleanFailure(r, 1, "rank 0 of 3 failed while writing: injected test fault");
    EXPECT_EQ(r.err.find("licvdb bake: error"), r.err.rfind("licvdb bake: error")) << r.describe();
}

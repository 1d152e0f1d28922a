// End to end, the .vdb read defences and the bake's output (issue 19): `licvdb info --check`
// exits 0 for intact files and 2 with the reason for corrupt ones; hundreds of mutants of
// several files fed to `info --check` and `bake` each exit 0 or 2, never crash, never take 10 s;
// concurrent bakes to one output leave a manifest that matches the .vdb beside it; a bake
// killed mid-way leaves no file, temporary or final.
#include "InputsHarness.h"

#include "../unit/CpuTime.h"
#include "../unit/VdbMutants.h"
#include "../unit/VdbSamples.h"

#include "vdbexport/io/Sha256.h"
#include "vdbexport/io/VdbCheck.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <cstring>
#include <set>

using namespace inputs_test;

namespace {

/// Names of the entries of `dir`.
std::set<std::string> listing(const fs::path& dir)
{
    std::set<std::string> out;
    for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
    return out;
}


/// The `seed` of the recipe stored in the `density` grid of a bake.
int64_t recipeSeedInFile(const fs::path& vdb)
{
    openvdb::io::File file(vdb.string());
    file.open(false);
    auto grid = file.readGridMetadata("density");
    file.close();
    const auto recipe = nlohmann::json::parse(grid->metaValue<std::string>("licvdb_recipe"));
    return recipe["input"]["seed"].get<int64_t>();
}

class VdbMutantsTest : public InputsTest
{};

} // namespace

TEST_F(VdbMutantsTest, InfoCheckExitsZeroForIntactFilesAndTwoWithTheReasonOtherwise)
{
    const fs::path w = work();
    const auto samples = vdb_samples::writeVdbSamples(w, 8);
    for (const auto& s : samples) {
        const RunResult r = run({"info", "--check", s});
        EXPECT_EQ(r.code, 0) << r.describe();
        EXPECT_NE(r.out.find("intact"), std::string::npos) << r.describe();
    }
    for (const auto& [path, words] : std::vector<std::pair<fs::path, std::string>>{
             {w / "missing.vdb", "not found"}, {w, "is a directory"}}) {
        const RunResult r = run({"info", "--check", path.string()});
        EXPECT_EQ(r.code, 2) << r.describe();
        EXPECT_NE(r.err.find(words), std::string::npos) << r.describe();
    }
    const RunResult j = run({"info", "--check", "--json", samples[0]});
    ASSERT_EQ(j.code, 0) << j.describe();
    const auto ok = nlohmann::json::parse(j.out);
    EXPECT_TRUE(ok["ok"].get<bool>());
    ASSERT_EQ(ok["grids"].size(), 1u); // the abc preset's velocity
    EXPECT_EQ(ok["grids"][0]["value_type"], "vec3s");
    EXPECT_GT(ok["grids"][0]["leaves"].get<int>(), 0);

    // The lie of issue 19: a vec3s leaf's blosc block claiming 8182 bytes (the leaf holds 6144).
    std::string bytes = readText(samples[0]);
    const std::size_t at = vdb_mutants::findBloscHeader(bytes, 6144);
    ASSERT_NE(at, std::string::npos);
    const uint32_t lie = 8182;
    std::memcpy(&bytes[at + 4], &lie, 4);
    writeBytes(w / "lying.vdb", bytes);
    for (const auto& args : std::vector<std::vector<std::string>>{{"info", "--check", (w / "lying.vdb").string()},
                                                                  {"info", (w / "lying.vdb").string()},
                                                                  {"render", (w / "lying.vdb").string(), "--out", "x.png"},
                                                                  bakeArgs(w / "lying.vdb", w / "out.vdb")}) {
        const RunResult r = run(args);
        EXPECT_EQ(r.code, 2) << r.describe();
        EXPECT_NE(r.err.find("claims 8182 bytes where 6144 are expected"), std::string::npos) << r.describe();
        EXPECT_NE(r.err.find("lying.vdb"), std::string::npos) << r.describe();
        // Refused by the structural check (layer 1), by name: its marker and rule begin the reason.
        EXPECT_NE(r.err.find("error: " + std::string(vdbexport::kVdbCheckMarker) + "blosc-nbytes] "), std::string::npos)
            << r.describe();
    }
    const RunResult bad = run({"info", "--check", "--json", (w / "lying.vdb").string()});
    EXPECT_EQ(bad.code, 2) << bad.describe();
    const auto no = nlohmann::json::parse(bad.out);
    EXPECT_FALSE(no["ok"].get<bool>());
    EXPECT_NE(no["error"].get<std::string>().find("8182"), std::string::npos);
    EXPECT_EQ(vdbexport::vdbCheckRule(no["error"].get<std::string>()), "blosc-nbytes");
    EXPECT_FALSE(fs::exists(w / "out.vdb"));
    EXPECT_FALSE(fs::exists(w / "x.png"));
}

// The child licvdb starts for every .vdb read (licvdb-readcheck, beside licvdb): exit 0 for an
// intact file, 2 with the same reason `licvdb info --check` gives for a corrupt one.
TEST_F(VdbMutantsTest, TheReadCheckChildRefusesWhatInfoCheckRefuses)
{
    const fs::path w = work();
    const auto samples = vdb_samples::writeVdbSamples(w, 16);
    const std::string helper = (fs::path(LICVDB_EXE).parent_path() / "licvdb-readcheck").string();
    ASSERT_TRUE(fs::exists(helper)) << helper;
    const std::string bytes = readText(samples[0]);
    writeBytes(w / "cut.vdb", bytes.substr(0, bytes.size() / 2));
    const RunResult ok = runCommand(cli_test::shellQuote(helper) + " -- " + cli_test::shellQuote(samples[0]));
    EXPECT_EQ(ok.code, 0) << ok.describe();
    const RunResult bad = runCommand(cli_test::shellQuote(helper) + " -- " + cli_test::shellQuote((w / "cut.vdb").string()));
    EXPECT_EQ(bad.code, 2) << bad.describe();
    const std::string prefix = "licvdb-readcheck: error: ";
    ASSERT_EQ(bad.err.rfind(prefix, 0), 0u) << bad.describe();
    const std::string reason = bad.err.substr(prefix.size(), bad.err.find('\n') - prefix.size());
    EXPECT_NE(reason.find("is truncated or corrupt"), std::string::npos) << bad.describe();
    const RunResult info = run({"info", "--check", (w / "cut.vdb").string()});
    EXPECT_EQ(info.code, 2) << info.describe();
    EXPECT_NE(info.err.find(reason), std::string::npos) << info.describe();
    const RunResult usage = runCommand(cli_test::shellQuote(helper));
    EXPECT_EQ(usage.code, 2) << usage.describe();
    EXPECT_NE(usage.err.find("usage: licvdb-readcheck -- FILE.vdb"), std::string::npos) << usage.describe();
}

// Mutants of three files (our field, a mantaflow-style half-float zip cache, a real bake): every
// `info --check` and every `bake` exits 0 or 2, and a refused bake writes nothing. Hang guard, safe
// on a busy machine (an ASan build beside other jobs once took 12 s of wall time for an intact
// file): each run is killed after kKillSeconds of wall time (a kill is not exit 0 or 2, so a real
// hang fails), and its CPU time (licvdb and its read child) must stay within 10x + 5 s of the same
// command on the intact file, measured in this test.
TEST_F(VdbMutantsTest, MutantsExitZeroOrTwoNeverCrashNeverHang)
{
    const fs::path w = work();
    const fs::path src = w / "src";
    fs::create_directories(src);
    const auto samples = vdb_samples::writeVdbSamples(src, 16);
    const RunResult baked = run(bakeArgs(samples[0], src / "bake.vdb", {"--quiet"}));
    ASSERT_EQ(baked.code, 0) << baked.describe();
    const std::vector<fs::path> files{samples[0], src / "mantaflow_half_zip.vdb", src / "bake.vdb"};
    const int perKind = std::getenv("LICVDB_CLI_MUTANTS_PER_KIND") ? std::atoi(std::getenv("LICVDB_CLI_MUTANTS_PER_KIND")) : 8;
    std::mt19937_64 rng(1919);
    int runs = 0, zero = 0, two = 0, bakes = 0;
    double slowest = 0, slowestRatio = 0;
    const fs::path m = w / "mutant.vdb";
    const fs::path outDir = w / "out";
    fs::create_directories(outDir);
    constexpr int kKillSeconds = 300;
    // `args` run under `timeout`; its CPU time (children's user + system) goes to `cpu`.
    const auto timed = [&](const std::vector<std::string>& args, double& cpu) {
        const double c0 = lictest::childrenCpuSeconds();
        const RunResult r = runCommand("timeout -s KILL " + std::to_string(kKillSeconds) + " " + cli_test::licvdbCommand(args));
        cpu = lictest::childrenCpuSeconds() - c0;
        return r;
    };
    for (const auto& file : files) {
        const std::string bytes = readText(file);
        // The same commands on the intact file: the CPU time a mutant's run is compared with.
        writeBytes(m, bytes);
        double intactCheck = 0, intactBake = 0;
        ASSERT_EQ(timed({"info", "--check", m.string()}, intactCheck).code, 0) << file;
        if (file != src / "bake.vdb") {
            const RunResult r = timed(bakeArgs(m, outDir / "lic.vdb", {"--quiet", "--length", "2"}), intactBake);
            ASSERT_EQ(r.code, 0) << r.describe();
            for (const auto& e : listing(outDir)) fs::remove(outDir / e);
        }
        for (int kind = 0; kind < vdb_mutants::kKinds; ++kind) {
            for (int n = 0; n < perKind; ++n) {
                writeBytes(m, vdb_mutants::mutate(bytes, kind, rng));
                SCOPED_TRACE(file.filename().string() + ", " + vdb_mutants::kindName(kind) + " #" + std::to_string(n));
                std::vector<std::vector<std::string>> commands{{"info", "--check", m.string()}};
                if (n % 2 == 0 && file != src / "bake.vdb")
                    commands.push_back(bakeArgs(m, outDir / "lic.vdb", {"--quiet", "--length", "2"}));
                for (const auto& args : commands) {
                    double cpu = 0;
                    const RunResult r = timed(args, cpu);
                    const double intact = args[0] == "bake" ? intactBake : intactCheck;
                    slowest = std::max(slowest, cpu);
                    slowestRatio = std::max(slowestRatio, cpu / std::max(intact, 1e-3));
                    ++runs;
                    EXPECT_TRUE(r.code == 0 || r.code == 2)
                        << (r.code == 128 + SIGKILL ? "killed after " + std::to_string(kKillSeconds) + " s: a hang\n" : "")
                        << r.describe();
                    EXPECT_LT(cpu, 10.0 * intact + 5.0) << "intact file: " << intact << " s of CPU time\n" << r.describe();
                    (r.code == 0 ? zero : two)++;
                    if (args[0] == "bake") {
                        ++bakes;
                        const auto left = listing(outDir);
                        if (r.code == 2) EXPECT_TRUE(left.empty()) << "a refused bake left " << *left.begin();
                        else EXPECT_EQ(left, (std::set<std::string>{"lic.licvdb.json", "lic.vdb"}));
                        for (const auto& e : left) fs::remove(outDir / e);
                    }
                }
            }
        }
    }
    std::cout << "[ mutants  ] " << runs << " runs (" << runs - bakes << " info --check, " << bakes << " bake) on mutants of "
              << files.size() << " files: " << zero << " exit 0, " << two << " exit 2, slowest " << slowest << " s of CPU time ("
              << slowestRatio << "x the intact file's)\n";
    EXPECT_GE(runs, perKind >= 8 ? 150 : 40);
}

// Two bakes with different seeds writing the same output, again and again: afterwards the
// manifest always describes the .vdb beside it (same seed, matching SHA-256).
TEST_F(VdbMutantsTest, ConcurrentBakesLeaveAManifestThatMatchesTheVdb)
{
    const fs::path w = work();
    const auto samples = vdb_samples::writeVdbSamples(w, 16);
    const std::string field = samples[0];
    const fs::path out = w / "same.vdb";
    for (int round = 0; round < 6; ++round) {
        std::string cmd;
        for (int seed = 1; seed <= 3; ++seed)
            cmd += cli_test::licvdbCommand(bakeArgs(field, out, {"--quiet", "--seed", std::to_string(seed + 10 * round)})) + " & ";
        const RunResult r = runCommand("( " + cmd + "wait )");
        ASSERT_EQ(r.code, 0) << r.describe();
        const auto manifest = nlohmann::json::parse(readText(w / "same.licvdb.json"));
        EXPECT_EQ(manifest["recipe"]["input"]["seed"].get<int64_t>(), recipeSeedInFile(out)) << "round " << round;
        EXPECT_EQ(manifest["sha256"]["same.vdb"].get<std::string>(), vdbexport::sha256OfFile(out.string()));
        for (const auto& name : listing(w)) EXPECT_EQ(name.find(".tmp-"), std::string::npos) << name;
    }
}

// A bake killed (SIGKILL) at any moment leaves either nothing or a complete, matching pair.
TEST_F(VdbMutantsTest, KilledBakeLeavesNoFile)
{
    const fs::path w = work();
    const fs::path in = w / "in";
    fs::create_directories(in);
    const auto samples = vdb_samples::writeVdbSamples(in, 24);
    const fs::path outDir = w / "out";
    fs::create_directories(outDir);
    const std::string bake = cli_test::licvdbCommand(
        bakeArgs(samples[0], outDir / "k.vdb", {"--quiet", "--length", "12", "--upsample", "2", "--frames", "3"}));
    // The kills land at fractions of a whole bake's time on this machine now (a fixed delay lets
    // a fast machine finish first), and once after it: the fastest of three whole bakes, so that
    // one slowed by a busy moment does not push the kills past the end of the next.
    double seconds = 1e9;
    for (int i = 0; i < 3; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        const RunResult whole = runCommand(bake);
        seconds = std::min(seconds, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        ASSERT_EQ(whole.code, 0) << whole.describe();
        for (const auto& e : listing(outDir)) fs::remove(outDir / e);
    }
    seconds = std::max(0.05, seconds);
    int killed = 0, finished = 0;
    for (const double fraction : {0.1, 0.25, 0.4, 0.55, 0.7, 1.5}) {
        const double delay = fraction * seconds;
        const RunResult r = runCommand("( " + bake + " & pid=$!; sleep " + std::to_string(delay) +
                                       "; kill -9 $pid 2>/dev/null && echo killed; wait $pid; true )");
        const auto left = listing(outDir);
        if (r.out.find("killed") != std::string::npos && left.empty()) {
            ++killed;
        } else {
            ++finished;
            ASSERT_EQ(left, (std::set<std::string>{"k.licvdb.json", "k_0001.vdb", "k_0002.vdb", "k_0003.vdb"})) << r.describe();
            const auto manifest = nlohmann::json::parse(readText(outDir / "k.licvdb.json"));
            for (const char* f : {"k_0001.vdb", "k_0002.vdb", "k_0003.vdb"})
                EXPECT_EQ(manifest["sha256"][f].get<std::string>(), vdbexport::sha256OfFile((outDir / f).string()));
        }
        for (const auto& e : left) fs::remove(outDir / e);
    }
    std::cout << "[ killed   ] " << killed << " bakes killed mid-way left nothing; " << finished
              << " had finished (the fastest whole bake: " << seconds << " s)\n";
    EXPECT_GE(killed, 3); // most kills land while the bake runs
}

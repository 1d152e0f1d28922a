// Tests of vdbexport/io/VdbCheck.h: the structural check of .vdb files accepts every kind of real
// file, refuses lying sizes before OpenVDB reads them, and hundreds of mutants of several files
// are each either read or refused with lic::InputError — never a crash (scripts/test-sanitize
// runs this under ASan + UBSan), never more than 10 s.
#include <gtest/gtest.h>

#include "CpuTime.h"
#include "TempDirSuite.h"
#include "VdbMutants.h"
#include "VdbSamples.h"

#include "vdbexport/io/Info.h"
#include "vdbexport/io/Sha256.h"
#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/FieldGrids.h"
#include "vdbexport/io/ReadCheck.h"
#include "vdbexport/io/VdbReader.h"

#include <lic/util/Error.h>

#include <cerrno>
#include <csignal>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <thread>

#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

using VdbCheckTest = lictest::TempDirTest;

using vdb_mutants::inputErrorOf;
using vdb_mutants::readFile;
using vdb_mutants::writeFile;

#define EXPECT_CONTAINS(haystack, needle) \
    EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "expected \"" << (needle) << "\" in: " << (haystack)

/// `sample` with its first full vec3s leaf's blosc header claiming 8182 bytes where the leaf holds
/// 512 × 12 = 6144, written to dir/name; "" if the sample has no such block.
std::string writeLyingLeaf(const std::string& sample, const fs::path& dir, const std::string& name)
{
    std::string bytes = readFile(sample);
    const std::size_t at = vdb_mutants::findBloscHeader(bytes, 6144);
    if (at == std::string::npos) return "";
    const uint32_t lie = 8182;
    std::memcpy(&bytes[at + 4], &lie, 4);
    const std::string path = (dir / name).string();
    writeFile(path, bytes);
    return path;
}


} // namespace

TEST_F(VdbCheckTest, AcceptsEveryKindOfRealFile)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir);
    ASSERT_EQ(samples.size(), 9u);
    for (const auto& path : samples) {
        SCOPED_TRACE(path);
        vdbexport::VdbCheckResult r;
        ASSERT_NO_THROW(r = vdbexport::checkVdbStructure(path));
        EXPECT_GE(r.fileVersion, 222u);
        EXPECT_FALSE(r.grids.empty());
        const auto d = vdbexport::describeVdb(path); // and OpenVDB reads every grid
        EXPECT_EQ(d["grids"].size(), r.grids.size());
        for (const auto& g : r.grids) EXPECT_TRUE(g.skipReason.empty()) << g.name << ": " << g.skipReason;
    }
    // What the check saw in the mixed file: half floats, an instance, tiles, leaves, every type.
    const auto r = vdbexport::checkVdbStructure((mDir / "all_types_blosc.vdb").string());
    std::map<std::string, vdbexport::VdbGridCheck> byName;
    for (const auto& g : r.grids) byName[g.name] = g;
    EXPECT_TRUE(byName.at("float_instance").instance);
    EXPECT_EQ(byName.at("float_instance").instanceParent, "float_tiles");
    EXPECT_EQ(byName.at("float_tiles").tiles, 1u); // the inactive root tile; the 128³ tile is internal
    EXPECT_EQ(byName.at("float_tiles").leaves, 3u);
    EXPECT_TRUE(byName.at("vec3d").halfFloat);
    EXPECT_EQ(byName.at("vec3d").valueType, "vec3d");
    EXPECT_EQ(byName.at("bool").valueType, "bool");
    EXPECT_EQ(byName.at("mask").valueType, "mask");
    EXPECT_EQ(byName.at("empty").leaves, 0u);
    const auto m = vdbexport::checkVdbStructure((mDir / "mantaflow_half_zip.vdb").string());
    EXPECT_EQ(m.grids.back().name, "velocity");
    EXPECT_TRUE(m.grids.back().halfFloat);
    EXPECT_EQ(m.grids.back().leafVoxelsOn, 16u * 16u * 16u);
}

// The crash of issue 19: a blosc block in a vec3s leaf that claims 8182 bytes where the leaf
// holds 512 × 12 = 6144. OpenVDB 10 copies it into the leaf buffer; the check refuses it first.
TEST_F(VdbCheckTest, LyingBloscSizeInAVec3LeafIsRefusedBeforeOpenVdbReadsIt)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir);
    const std::string path = writeLyingLeaf(samples[0], mDir, "lying.vdb");
    ASSERT_FALSE(path.empty()) << "no full vec3s leaf block in the sample";
    const std::string msg = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    EXPECT_CONTAINS(msg, "lying.vdb");
    EXPECT_CONTAINS(msg, "is corrupt");
    EXPECT_CONTAINS(msg, "grid 'velocity'");
    EXPECT_CONTAINS(msg, "leaf at (");
    EXPECT_CONTAINS(msg, "claims 8182 bytes where 6144 are expected");
    EXPECT_EQ(msg.rfind(std::string(vdbexport::kVdbCheckMarker) + "blosc-nbytes] ", 0), 0u) << msg; // by the check
    // Every read path refuses it.
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::readVelocityGrid(path); }), "8182");
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::describeVdb(path); }), "8182");
    // The block's stored length word made huge is refused by name too.
    std::string bytes2 = readFile(samples[0]);
    const std::size_t at = vdb_mutants::findBloscHeader(bytes2, 6144);
    const int64_t huge = int64_t(1) << 40;
    std::memcpy(&bytes2[at - 8], &huge, 8);
    writeFile(path, bytes2);
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkVdbStructure(path); }), "compress to at most");
}

TEST_F(VdbCheckTest, HugeCountsAreRefusedAtOnce)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir);
    const std::string bytes = readFile(samples[0]);
    const std::string path = (mDir / "huge.vdb").string();
    // The file metadata count sits right after the 57-byte header.
    std::string m = bytes;
    const uint32_t big = 0xFFFFFFFFu;
    std::memcpy(&m[57], &big, 4);
    writeFile(path, m);
    // At once: no attempt to read or allocate 4 billion entries (CPU time, not wall time: a busy
    // machine does not make it fail).
    const double cpu0 = lictest::processCpuSeconds();
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkVdbStructure(path); }), "4294967295 metadata entries");
    EXPECT_LT(lictest::processCpuSeconds() - cpu0, 1.0);
}

TEST_F(VdbCheckTest, UnsupportedFormatVersionIsNamed)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir);
    std::string bytes = readFile(samples[0]);
    const uint32_t old = 220;
    std::memcpy(&bytes[8], &old, 4);
    const std::string path = (mDir / "old.vdb").string();
    writeFile(path, bytes);
    const std::string msg = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    EXPECT_CONTAINS(msg, "format version 220");
    // OpenVDB 13's format (225) is read whatever OpenVDB licvdb is built with (10 or 13).
    EXPECT_CONTAINS(msg, "222 to 225 (OpenVDB 2.0 to 13.x)");
    // A version newer than any OpenVDB licvdb knows: refused with the same range.
    const uint32_t newer = 226;
    std::memcpy(&bytes[8], &newer, 4);
    writeFile(path, bytes);
    const std::string msg2 = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    EXPECT_CONTAINS(msg2, "format version 226");
    EXPECT_CONTAINS(msg2, "222 to 225 ");
}

// A file OpenVDB 13 wrote (format 225, e.g. a Blender 5 smoke cache): only its half-precision
// grid type is new (tests/inputs/openvdb13/make_samples.py), so the check passes it and the
// OpenVDB licvdb is built with reads its float and vec3s grids (half-float storage included)
// with the values OpenVDB 13 wrote.
TEST_F(VdbCheckTest, OpenVdb13FilesAreRead)
{
    const std::string path = std::string(LICVDB_SOURCE_DIR) + "/tests/inputs/openvdb13/velocity-v225.vdb";
    const vdbexport::VdbCheckResult r = vdbexport::checkVdbStructure(path);
    EXPECT_EQ(r.fileVersion, 225u);
    EXPECT_EQ(r.libraryMajor, 13u);
    ASSERT_EQ(r.grids.size(), 2u);
    vdbexport::detail::VdbReader reader(path);
    auto vel = openvdb::gridPtrCast<openvdb::Vec3SGrid>(reader.readGrid("velocity"));
    auto den = openvdb::gridPtrCast<openvdb::FloatGrid>(reader.readGrid("density"));
    ASSERT_TRUE(vel && den);
    EXPECT_TRUE(den->saveFloatAsHalf());
    EXPECT_EQ(vel->activeVoxelCount(), 4096u);
    EXPECT_EQ(den->activeVoxelCount(), 4096u);
    EXPECT_DOUBLE_EQ(vel->voxelSize()[0], 0.1);
    int wrong = 0;
    auto va = vel->getConstAccessor();
    auto da = den->getConstAccessor();
    for (int i = 0; i < 16; ++i)
        for (int j = 0; j < 16; ++j)
            for (int k = 0; k < 16; ++k) {
                const openvdb::Coord c(i, j, k);
                const openvdb::Vec3s want(float(-(j - 7.5)), float(i - 7.5), 0.25f);
                const float wantDensity = float(openvdb::math::half(float(0.05 * (k + 1)))); // stored as half
                if (va.getValue(c) != want || da.getValue(c) != wantDensity) ++wrong;
            }
    EXPECT_EQ(wrong, 0);
}

// OpenVDB 13's HalfGrid (Tree_half_5_4_3) is named, not called corrupt or "not an OpenVDB type".
TEST_F(VdbCheckTest, HalfGridIsRefusedByName)
{
    // The OpenVDB 13 sample with its first grid's type name (length-prefixed) made the half
    // type's: the refusal comes before anything after the name is read.
    std::string bytes = readFile(std::string(LICVDB_SOURCE_DIR) + "/tests/inputs/openvdb13/velocity-v225.vdb");
    const std::string vecType = openvdb::Vec3SGrid::gridType(), halfType = "Tree_half_5_4_3";
    const std::size_t at = bytes.find(vecType);
    ASSERT_NE(at, std::string::npos);
    const uint32_t n = uint32_t(halfType.size());
    std::memcpy(&bytes[at - 4], &n, 4);
    bytes.replace(at, vecType.size(), halfType);
    const std::string path = (mDir / "half.vdb").string();
    writeFile(path, bytes);
    const std::string msg = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    EXPECT_CONTAINS(msg, "[vdb-check half-grid]");
    EXPECT_CONTAINS(msg, "half-precision grid (Tree_half_5_4_3");
    EXPECT_CONTAINS(msg, "save it as a float grid");
}

// Hundreds of mutants of nine files (byte flips, truncations, huge 4- and 8-byte words, sizes off
// by a little): each is read or refused with lic::InputError by every read path, in well under
// 10 s; none crashes (under ASan: none corrupts memory).
TEST_F(VdbCheckTest, MutantsAreReadOrRefusedNeverCrash)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir);
    const int perKind = std::getenv("LICVDB_MUTANTS_PER_KIND") ? std::atoi(std::getenv("LICVDB_MUTANTS_PER_KIND")) : 12;
    std::mt19937_64 rng(19);
    const std::string path = (mDir / "mutant.vdb").string();
    int total = 0, refused = 0, read = 0, byCheck = 0;
    double maxSeconds = 0;
    std::map<std::string, int> reasons;
    for (const auto& sample : samples) {
        const std::string bytes = readFile(sample);
        for (int kind = 0; kind < vdb_mutants::kKinds; ++kind) {
            for (int n = 0; n < perKind; ++n) {
                const std::string m = vdb_mutants::mutate(bytes, kind, rng);
                writeFile(path, m);
                vdbexport::detail::clearCheckedVdbCache();
                SCOPED_TRACE(fs::path(sample).filename().string() + ", " + vdb_mutants::kindName(kind) + " #" + std::to_string(n));
                const double cpu0 = lictest::processCpuSeconds();
                bool ok = true;
                try {
                    (void)vdbexport::describeVdb(path);
                    try {
                        (void)vdbexport::readVelocityGrid(path);
                    } catch (const lic::InputError& e) {
                        // readable, but no usable velocity grid: that is fine too
                        if (std::string(e.what()).find("corrupt") != std::string::npos) ok = false;
                    }
                    (void)vdbexport::readScalarGrids(path);
                } catch (const lic::InputError& e) {
                    ok = false;
                    const std::string w = e.what();
                    // By the structural check (its marker names the rule), or later by OpenVDB.
                    const std::string rule = vdbexport::vdbCheckRule(w);
                    byCheck += rule.empty() ? 0 : 1;
                    reasons[rule.empty() ? "by OpenVDB's reader: " + w : "by the check, rule " + rule]++;
                    if (std::getenv("LICVDB_SHOW_MUTANT_ERRORS")) std::cout << w << "\n";
                    EXPECT_CONTAINS(w, "mutant.vdb");
                } catch (const std::exception& e) {
                    ADD_FAILURE() << "not an InputError: " << e.what();
                }
                // A runaway loop or a huge allocation spends CPU time; a busy machine only wall time.
                const double s = lictest::processCpuSeconds() - cpu0;
                maxSeconds = std::max(maxSeconds, s);
                EXPECT_LT(s, 10.0);
                ++total;
                (ok ? read : refused)++;
            }
        }
    }
    std::cout << "[ mutants  ] " << total << " mutants of " << samples.size() << " files: " << read << " read, "
              << refused << " refused, slowest " << maxSeconds << " s of CPU time\n";
    for (const auto& [why, count] : reasons) std::cout << "[ mutants  ]   refused, " << why << ": " << count << "\n";
    EXPECT_GE(total, 500);
    EXPECT_GT(refused, total / 4); // the mutations do hit: most mutants are refused
    // Layer 1 refuses them before OpenVDB reads them: a rule that stops refusing shows up here
    // even where OpenVDB would notice the same damage (one in 409 at the default counts).
    std::cout << "[ mutants  ] " << byCheck << " of " << refused << " refusals by the structural check\n";
    EXPECT_GE(byCheck * 50, refused * 49);
}

// ---- layer 2: the isolated child process ------------------------------------------------------
// A stand-in for `licvdb` (a shell script) shows what the parent makes of each way a child ends.

namespace {

struct IsolationGuard
{
    ~IsolationGuard()
    {
        vdbexport::setReadIsolation("");
        ::unsetenv("LICVDB_READ_TIMEOUT");
    }
};

std::string script(const fs::path& dir, const std::string& name, const std::string& body)
{
    const fs::path p = dir / name;
    writeFile(p.string(), "#!/bin/sh\n" + body + "\n");
    fs::permissions(p, fs::perms::owner_all);
    return p.string();
}

} // namespace

TEST_F(VdbCheckTest, IsolatedChildOutcomes)
{
    const IsolationGuard guard;
    const auto samples = vdb_samples::writeVdbSamples(mDir, 8);
    const std::string file = samples[0];
    // Intact: exit 0. The child is run as `EXE info --check --quiet -- FILE` with LICVDB_READ_CHILD=1.
    vdbexport::setReadIsolation(script(mDir, "ok.sh",
        "[ \"$1 $2 $3 $4\" = 'info --check --quiet --' ] && [ \"$LICVDB_READ_CHILD\" = 1 ] && [ -f \"$5\" ] || exit 1\nexit 0"));
    EXPECT_NO_THROW(vdbexport::checkInIsolatedProcess(file));
    // Refused with a reason: exit 2, the reason from its stderr.
    vdbexport::setReadIsolation(script(mDir, "bad.sh", "echo 'licvdb info: error: the reason given' >&2\nexit 2"));
    EXPECT_EQ(inputErrorOf([&] { vdbexport::checkInIsolatedProcess(file); }), "the reason given");
    // A crash of the reader: the file is refused, naming the signal.
    vdbexport::setReadIsolation(script(mDir, "crash.sh", "kill -SEGV $$"));
    const std::string crash = inputErrorOf([&] { vdbexport::checkInIsolatedProcess(file); });
    EXPECT_CONTAINS(crash, "crashed OpenVDB's reader");
    EXPECT_CONTAINS(crash, "signal 11");
    // A hang: killed after LICVDB_READ_TIMEOUT seconds.
    ::setenv("LICVDB_READ_TIMEOUT", "1", 1);
    vdbexport::setReadIsolation(script(mDir, "hang.sh", "exec sleep 60"));
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkInIsolatedProcess(file); }), "did not finish within 1 s");
    // Killed at the time-out, long before the child's 60 s sleep ends (a generous bound: the
    // machine may be busy).
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 30.0);
    // Another failure of the child is a runtime error (exit 1), not bad input.
    vdbexport::setReadIsolation(script(mDir, "fail.sh", "echo 'licvdb info: error: out of memory' >&2\nexit 1"));
    EXPECT_THROW(vdbexport::checkInIsolatedProcess(file), lic::Error);
    try {
        vdbexport::checkInIsolatedProcess(file);
    } catch (const lic::InputError&) {
        ADD_FAILURE() << "exit 1 must not be reported as bad input";
    } catch (const lic::Error&) {
    }
    // Off: nothing is run.
    vdbexport::setReadIsolation("");
    EXPECT_NO_THROW(vdbexport::checkInIsolatedProcess(file));
}

// checkedVdb starts the child before its own layer 1 and lets the two run side by side. A check
// dropped unfinished stops its child (killed and reaped, no zombie left); a file refused by layer 1
// here gets layer 1's message at once, not the child's (which here would hang for a minute).
TEST_F(VdbCheckTest, TheChildRunsBesideLayerOneAndIsStoppedWhenLayerOneRefuses)
{
    const IsolationGuard guard;
    const auto samples = vdb_samples::writeVdbSamples(mDir, 8);
    const fs::path pidFile = mDir / "child.pid";
    vdbexport::setReadIsolation(script(mDir, "hang.sh", "echo $$ > '" + pidFile.string() + "'\nexec sleep 60"));
    ::setenv("LICVDB_READ_TIMEOUT", "60", 1);

    pid_t child = -1;
    {
        vdbexport::IsolatedCheck check = vdbexport::startIsolatedCheck(samples[0]);
        // The pid is there once its line is written in full (up to its newline).
        std::string written;
        for (int i = 0; i < 3000; ++i) {
            if (fs::exists(pidFile)) written = readFile(pidFile.string());
            if (!written.empty() && written.back() == '\n') break;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        ASSERT_TRUE(!written.empty() && written.back() == '\n') << "the child did not start";
        child = pid_t(std::stol(written));
        ASSERT_GT(child, 0);
        EXPECT_EQ(::kill(child, 0), 0) << "the child runs while the check is held";
    } // dropped unfinished
    errno = 0;
    EXPECT_EQ(::kill(child, 0), -1);
    EXPECT_EQ(errno, ESRCH) << "the dropped check's child is still there (not killed or not reaped)";

    const std::string path = writeLyingLeaf(samples[0], mDir, "lying-beside.vdb");
    ASSERT_FALSE(path.empty()) << "no full vec3s leaf block in the sample";
    vdbexport::detail::clearCheckedVdbCache();
    const std::string layerOne = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_EQ(inputErrorOf([&] { vdbexport::detail::checkedVdb(path); }), layerOne);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 30.0)
        << "waited for the hanging child although layer 1 had refused the file";
}

// The fork server (startReadCheckServer): each check is a child forked from a process made at
// start-up, handed to this one, and ends in the same verdicts as a started program. The set
// executable (/bin/false, which fails every check) shows that the server, not a program, ran each
// check; once the server has gone, checks start the program again.
TEST_F(VdbCheckTest, ForkServerChildOutcomes)
{
    // First, before anything here starts a thread (writing the samples below uses TBB).
    const auto check = [](const std::string& path) -> int {
        if (path.find("crash") != std::string::npos) std::abort(); // (a sanitizer turns SIGSEGV into exit 1)
        if (path.find("hang") != std::string::npos) std::this_thread::sleep_for(std::chrono::seconds(60));
        if (path.find("pid") != std::string::npos) { // say who runs the check, then pass
            std::ofstream(path) << ::getpid() << " " << ::getppid() << "\n";
            return 0;
        }
        return vdbexport::detail::readCheckMain(path, "licvdb-readcheck");
    };
    ASSERT_TRUE(vdbexport::startReadCheckServer(check));
    struct ServerGuard
    {
        ~ServerGuard() { vdbexport::stopReadCheckServer(); }
    } serverGuard;
    const IsolationGuard guard;
    const pid_t server = vdbexport::readCheckServerPid();
    ASSERT_GT(server, 0);
    vdbexport::setReadIsolation("/bin/false");

    const auto samples = vdb_samples::writeVdbSamples(mDir, 8);
    // Intact: the real read, in a child of the server's handed to this process.
    EXPECT_NO_THROW(vdbexport::checkInIsolatedProcess(samples[0]));
    const std::string who = (mDir / "pid.txt").string();
    EXPECT_NO_THROW(vdbexport::checkInIsolatedProcess(who));
    std::istringstream ids(readFile(who));
    pid_t childPid = -1, childParent = -1;
    ids >> childPid >> childParent;
    EXPECT_GT(childPid, 0);
    EXPECT_NE(childPid, server);
    EXPECT_NE(childPid, ::getpid());
    // Forked by an intermediate process that then exits: its parent is that process or, once
    // handed over, this one (the subreaper); never the server.
    EXPECT_GT(childParent, 0);
    EXPECT_NE(childParent, server);
    // Refused: layer 1's reason, from the child's stderr.
    const std::string junk = (mDir / "junk.vdb").string();
    writeFile(junk, "not a vdb file at all, just some text that is long enough");
    const std::string refused = inputErrorOf([&] { vdbexport::checkInIsolatedProcess(junk); });
    EXPECT_CONTAINS(refused, "not-vdb");
    // A crash (an abort): refused, naming the signal; the server lives on.
    const std::string crashFile = (mDir / "crash.vdb").string();
    writeFile(crashFile, "x");
    const std::string crash = inputErrorOf([&] { vdbexport::checkInIsolatedProcess(crashFile); });
    EXPECT_CONTAINS(crash, "crashed OpenVDB's reader");
    EXPECT_CONTAINS(crash, "signal 6");
    EXPECT_EQ(vdbexport::readCheckServerPid(), server);
    // A hang: killed after LICVDB_READ_TIMEOUT seconds (a generous bound on the wait: busy machines).
    ::setenv("LICVDB_READ_TIMEOUT", "1", 1);
    const std::string hangFile = (mDir / "hang.vdb").string();
    writeFile(hangFile, "x");
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkInIsolatedProcess(hangFile); }), "did not finish within 1 s");
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 30.0);
    ::unsetenv("LICVDB_READ_TIMEOUT");
    // Every child was this process's to wait for, and was waited for: none is left but the server.
    int status = 0;
    EXPECT_EQ(::waitpid(-1, &status, WNOHANG), 0) << "a child has ended and was not reaped";
    // The server gone: checks start the set program (here /bin/false: a failure, not bad input).
    ASSERT_EQ(::kill(server, SIGKILL), 0);
    ASSERT_EQ(::waitpid(server, &status, 0), server);
    EXPECT_THROW(vdbexport::checkInIsolatedProcess(samples[0]), lic::Error);
    EXPECT_EQ(vdbexport::readCheckServerPid(), -1);
    vdbexport::setReadIsolation("");
    EXPECT_NO_THROW(vdbexport::checkInIsolatedProcess(samples[0]));
}

TEST(Sha256, KnownDigests)
{
    vdbexport::Sha256 empty;
    EXPECT_EQ(empty.hex(), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    vdbexport::Sha256 abc;
    abc.update("abc", 3);
    EXPECT_EQ(abc.hex(), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    vdbexport::Sha256 two; // 448 bits: the padding spills into a second block
    const std::string s = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
    two.update(s.data(), s.size());
    EXPECT_EQ(two.hex(), "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
    vdbexport::Sha256 million; // a million 'a', fed in odd pieces
    const std::string chunk(999, 'a');
    std::size_t left = 1000000;
    while (left > 0) {
        const std::size_t n = std::min(left, chunk.size());
        million.update(chunk.data(), n);
        left -= n;
    }
    EXPECT_EQ(million.hex(), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

// Found by fuzz_vdb (corpus/vdb/regress-half-flag-metadata): OpenVDB 10 takes a grid's half-float
// flag from its `is_saved_as_half_float` metadata, not from the descriptor's `_HalfFloat`. With
// the metadata renamed, OpenVDB reads half-float blocks as full floats and met a length word
// in the middle of data (a 241 GB allocation); the check must read the flag the same way.
TEST_F(VdbCheckTest, HalfFloatFlagIsTakenFromTheMetadataAsOpenVdbDoes)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir, 8);
    std::string bytes = readFile((mDir / "mantaflow_half_blosc.vdb").string());
    const std::string key = "is_saved_as_half_float";
    std::size_t renamed = 0;
    for (std::size_t at = bytes.find(key); at != std::string::npos; at = bytes.find(key, at + 1), ++renamed)
        bytes.replace(at + key.size() - 5, 5, "doubl");
    ASSERT_EQ(renamed, 3u); // density, flame, velocity
    const std::string path = (mDir / "renamed.vdb").string();
    writeFile(path, bytes);
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkVdbStructure(path); }), "is corrupt");
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::describeVdb(path); }), "is corrupt");
    // The fuzzer's own reproducer.
    const std::string regress = std::string(LICVDB_SOURCE_DIR) + "/tests/fuzz/corpus/vdb/regress-half-flag-metadata";
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkVdbStructure(regress); }), "is corrupt");
    // The flag itself of another type is refused by name.
    std::string typed = readFile((mDir / "mantaflow_half_blosc.vdb").string());
    const std::size_t at = typed.find(key);
    ASSERT_NE(at, std::string::npos);
    const std::size_t typeAt = at + key.size() + 4; // the type name "bool" after its length
    ASSERT_EQ(typed.substr(typeAt, 4), "bool");
    typed.replace(typeAt, 4, "bogo");
    writeFile(path, typed);
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkVdbStructure(path); }), "half-float flag is a bogo");
}

// What licvdb checks of a file it has just written (OutputSet::addVdb): the layout without decoding
// the compressed blocks. It must still refuse every file cut short (a full disk) and every lying
// block header, as the full check does.
TEST_F(VdbCheckTest, TheLayoutCheckOfAWrittenFileRefusesEveryCutAsTheFullCheckDoes)
{
    const auto samples = vdb_samples::writeVdbSamples(mDir);
    ASSERT_GE(samples.size(), 3u);
    int cuts = 0;
    for (const auto& sample : samples) {
        const std::string bytes = readFile(sample);
        const auto full = vdbexport::checkVdbStructure(sample);
        const auto layout = vdbexport::checkVdbStructure(sample, vdbexport::VdbCheckDepth::Layout);
        ASSERT_EQ(layout.grids.size(), full.grids.size()) << sample;
        for (std::size_t i = 0; i < full.grids.size(); ++i) EXPECT_EQ(layout.grids[i].name, full.grids[i].name);
        const std::string cut = (mDir / "cut.vdb").string();
        for (int k = 1; k < 24; ++k) {
            const std::size_t n = bytes.size() * std::size_t(k) / 24;
            writeFile(cut, bytes.substr(0, n));
            const std::string msg = inputErrorOf([&] { vdbexport::checkVdbStructure(cut, vdbexport::VdbCheckDepth::Layout); });
            EXPECT_FALSE(msg.empty()) << sample << " cut to " << n << " of " << bytes.size() << " bytes was accepted";
            EXPECT_FALSE(inputErrorOf([&] { vdbexport::checkVdbStructure(cut); }).empty());
            ++cuts;
        }
    }
    EXPECT_GE(cuts, 60);
    // A lying blosc header (the block claims more bytes than its leaf holds) is refused without decoding.
    const std::string path = writeLyingLeaf(samples[0], mDir, "lying.vdb");
    ASSERT_FALSE(path.empty()) << "no full vec3s leaf block in the sample";
    EXPECT_CONTAINS(inputErrorOf([&] { vdbexport::checkVdbStructure(path, vdbexport::VdbCheckDepth::Layout); }),
                    "claims 8182 bytes where 6144 are expected");
}

// What a bake leaves on disk when it dies while writing, proved at the exact points it could die
// (the commit hook $LICVDB_TEST_COMMIT_HOOK of vdbexport::OutputSet, read only by tests): after
// staging every file and before linking any, nothing; between the frames and the manifest, the new
// frames and no manifest (frames first, manifest last); the same with named temporaries, as on a
// file system without O_TMPFILE ($LICVDB_TEST_NO_O_TMPFILE), where the temporaries a killed bake
// left are removed by the next bake to the same output; and a second bake to the same output
// waits for the first one's directory lock.
#include <gtest/gtest.h>

#include "CliRun.h"
#include "../unit/ManifestDigests.h"
#include "../unit/TempDirSuite.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace fs = std::filesystem;
using cli_test::RunResult;

namespace {

class WriteOrder : public lictest::TempDirSuite<WriteOrder>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("write_order", "logs");
        const RunResult r = cli_test::runLicvdb(sDir, sDir / "logs", {"field", "abc", "--res", "12,12,12", "--out", "abc.vdb", "--quiet"});
        ASSERT_EQ(r.code, 0) << r.describe();
    }
    void SetUp() override { mOut = testDir(); }

    /// A 3-frame loop of the abc field into mOut/loop*, with `env` ("NAME=VALUE" …) set.
    RunResult bake(const std::vector<std::string>& env)
    {
        std::string cmd = "env";
        for (const auto& e : env) cmd += " " + cli_test::shellQuote(e);
        cmd += " " + cli_test::licvdbCommand({"bake", "--field", (sDir / "abc.vdb").string(), "--out",
                                              (mOut / "loop.vdb").string(), "--length", "3", "--frames", "3", "--quiet"});
        return cli_test::runShell(mOut, sDir / "logs", cmd);
    }

    /// The same bake started in the background; returns its pid.
    pid_t spawnBake(const std::vector<std::string>& env)
    {
        std::vector<std::string> args{LICVDB_EXE, "bake", "--field", (sDir / "abc.vdb").string(), "--out",
                                      (mOut / "loop.vdb").string(), "--length", "3", "--frames", "3", "--quiet"};
        std::vector<std::string> envs;
        for (char** e = environ; *e; ++e) envs.emplace_back(*e);
        envs.insert(envs.end(), env.begin(), env.end());
        std::vector<char*> argv, envp;
        for (auto& a : args) argv.push_back(a.data());
        argv.push_back(nullptr);
        for (auto& e : envs) envp.push_back(e.data());
        envp.push_back(nullptr);
        posix_spawn_file_actions_t actions;
        posix_spawn_file_actions_init(&actions);
        posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
        posix_spawn_file_actions_addopen(&actions, 2, (sDir / "logs" / "spawned.err").c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
        pid_t pid = -1;
        const int rc = posix_spawn(&pid, LICVDB_EXE, &actions, nullptr, argv.data(), envp.data());
        posix_spawn_file_actions_destroy(&actions);
        EXPECT_EQ(rc, 0) << "could not start " << LICVDB_EXE;
        return pid;
    }

    /// The names in mOut.
    std::set<std::string> listing() const
    {
        std::set<std::string> names;
        for (const auto& e : fs::directory_iterator(mOut)) names.insert(e.path().filename().string());
        return names;
    }

    fs::path mOut;
};

const std::set<std::string> kFrames{"loop_0001.vdb", "loop_0002.vdb", "loop_0003.vdb"};

std::set<std::string> with(std::set<std::string> a, const std::set<std::string>& b)
{
    a.insert(b.begin(), b.end());
    return a;
}

/// Wait (generously: the machine may be busy) until process `pid` is stopped; false if it ended.
bool waitStopped(pid_t pid)
{
    for (int i = 0; i < 1200; ++i) {
        int status = 0;
        const pid_t r = ::waitpid(pid, &status, WUNTRACED | WNOHANG);
        if (r == pid) return WIFSTOPPED(status);
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
}

/// Wait for a file to appear (generously); false if it did not.
bool waitForFile(const fs::path& p)
{
    for (int i = 0; i < 1200; ++i) {
        if (fs::exists(p)) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
}

int exitCodeOf(pid_t pid)
{
    int status = 0;
    ::waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

} // namespace

TEST_F(WriteOrder, KilledAfterStagingLeavesNothing)
{
    const RunResult r = bake({"LICVDB_TEST_COMMIT_HOOK=staged kill"});
    EXPECT_EQ(r.code, 128 + SIGKILL) << r.describe();
    EXPECT_TRUE(listing().empty()) << "a bake killed before linking left files";
}

TEST_F(WriteOrder, FramesFirstManifestLast)
{
    // Killed after the three frames were renamed into place, before the manifest was.
    const RunResult r = bake({"LICVDB_TEST_COMMIT_HOOK=linked:3 kill"});
    EXPECT_EQ(r.code, 128 + SIGKILL) << r.describe();
    EXPECT_EQ(listing(), kFrames) << "expected the frames without their manifest";
    // Killed after the first frame: the others and the manifest are not there.
    fs::remove_all(mOut);
    fs::create_directories(mOut);
    EXPECT_EQ(bake({"LICVDB_TEST_COMMIT_HOOK=linked:1 kill"}).code, 128 + SIGKILL);
    EXPECT_EQ(listing(), std::set<std::string>{"loop_0001.vdb"});
    // Whole, the manifest is last and describes the frames on disk.
    const RunResult whole = bake({});
    ASSERT_EQ(whole.code, 0) << whole.describe();
    EXPECT_EQ(listing(), with(kFrames, {"loop.licvdb.json"}));
    lictest::expectManifestDigests(mOut / "loop.licvdb.json", 3);
}

TEST_F(WriteOrder, NamedTemporariesWithoutOTmpfile)
{
    const std::string noTmpfile = "LICVDB_TEST_NO_O_TMPFILE=1";
    // The fallback writes the same files and leaves no temporary.
    const RunResult ok = bake({noTmpfile});
    ASSERT_EQ(ok.code, 0) << ok.describe();
    EXPECT_EQ(listing(), with(kFrames, {"loop.licvdb.json"}));
    lictest::expectManifestDigests(mOut / "loop.licvdb.json", 3);
    // Killed after staging: the named temporaries remain (SIGKILL cannot be caught), no final
    // file is replaced or added.
    const std::string before = cli_test::readText(mOut / "loop.licvdb.json");
    fs::remove(mOut / "loop_0002.vdb");
    const RunResult killed = bake({noTmpfile, "LICVDB_TEST_COMMIT_HOOK=staged kill"});
    EXPECT_EQ(killed.code, 128 + SIGKILL) << killed.describe();
    std::set<std::string> finals, temporaries;
    for (const auto& name : listing()) (name.find(".tmp-") == std::string::npos ? finals : temporaries).insert(name);
    EXPECT_EQ(finals, (std::set<std::string>{"loop_0001.vdb", "loop_0003.vdb", "loop.licvdb.json"}));
    EXPECT_EQ(temporaries.size(), 4u) << "three frames and the manifest staged under temporary names";
    EXPECT_EQ(cli_test::readText(mOut / "loop.licvdb.json"), before) << "the old manifest was touched";
    // The next bake to the same output removes what the killed one left.
    const RunResult next = bake({noTmpfile});
    ASSERT_EQ(next.code, 0) << next.describe();
    EXPECT_EQ(listing(), with(kFrames, {"loop.licvdb.json"}));
    lictest::expectManifestDigests(mOut / "loop.licvdb.json", 3);
}

TEST_F(WriteOrder, ASecondBakeWaitsForTheFirstOnesLock)
{
    // Bake A stops holding the directory lock, one frame renamed. Bake B to the same output stages
    // its files, says so, and must then wait: no frame of its own and no manifest appear until A
    // goes on. Then both finish, and the output is one bake's whole (the manifest's digests are
    // its files').
    const pid_t a = spawnBake({"LICVDB_TEST_COMMIT_HOOK=linked:1 stop"});
    ASSERT_TRUE(waitStopped(a)) << "bake A never reached its commit";
    const std::set<std::string> held = listing();
    EXPECT_EQ(held, std::set<std::string>{"loop_0001.vdb"});
    const fs::path staged = mOut.parent_path() / (mOut.filename().string() + ".b-staged");
    const pid_t b = spawnBake({"LICVDB_TEST_COMMIT_HOOK=staged touch:" + staged.string()});
    ASSERT_TRUE(waitForFile(staged)) << "bake B never reached its commit";
    std::this_thread::sleep_for(std::chrono::seconds(2));
    int status = 0;
    EXPECT_EQ(::waitpid(b, &status, WNOHANG), 0) << "bake B finished while A held the lock";
    EXPECT_EQ(listing(), held) << "bake B wrote while A held the lock";
    ::kill(a, SIGCONT);
    EXPECT_EQ(exitCodeOf(a), 0);
    EXPECT_EQ(exitCodeOf(b), 0);
    fs::remove(staged);
    EXPECT_EQ(listing(), with(kFrames, {"loop.licvdb.json"}));
    lictest::expectManifestDigests(mOut / "loop.licvdb.json", 3);
}

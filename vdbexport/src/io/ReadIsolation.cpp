// checkInIsolatedProcess(): layer 2 of the read defences (docs/inputs.md). A child process
// (`licvdb-readcheck -- FILE` where it is installed, else `licvdb info --check FILE` with
// LICVDB_READ_CHILD=1 so that it reads in-process) reads every grid with OpenVDB; whatever a file does to that reader (a crash, memory corruption, a hang) stays
// in the child, which is killed after a time limit.
#include "vdbexport/io/VdbCheck.h"

#include <lic/util/Error.h>

#include <chrono>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string>
#include <sys/stat.h>
#include <thread>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace vdbexport {

namespace {

std::mutex sExeMutex;
std::string sExecutable, sVdbHelper;

std::string quote(const std::string& s) { return "'" + s + "'"; }

/// The child's reason: the text after "error: " on its first error line, else its whole stderr.
std::string childReason(const std::string& err)
{
    const auto at = err.find("error: ");
    std::string line = at == std::string::npos ? err : err.substr(at + 7);
    if (const auto nl = line.find('\n'); nl != std::string::npos) line.resize(nl);
    if (line.size() > 400) line = line.substr(0, 400) + "...";
    return line;
}

} // namespace

void setReadIsolation(const std::string& executable, const std::string& vdbHelper)
{
    const std::lock_guard<std::mutex> lock(sExeMutex);
    sExecutable = executable;
    sVdbHelper = executable.empty() ? std::string() : vdbHelper;
}

std::string findVdbReadHelper(const std::string& executable)
{
    if (executable.empty()) return "";
    const std::filesystem::path dir = std::filesystem::path(executable).parent_path();
    for (const std::filesystem::path& p : {dir / "licvdb-readcheck", dir / ".." / "libexec" / "licvdb" / "licvdb-readcheck"})
        if (::access(p.c_str(), X_OK) == 0) return p.lexically_normal().string();
    return "";
}

std::string readIsolationExecutable()
{
    const std::lock_guard<std::mutex> lock(sExeMutex);
    return sExecutable;
}

double readTimeoutSeconds(uint64_t fileBytes)
{
    if (const char* env = std::getenv("LICVDB_READ_TIMEOUT")) {
        char* end = nullptr;
        const double t = std::strtod(env, &end);
        if (end != env && t > 0) return t;
    }
    return 20.0 + double(fileBytes) / 10e6;
}

IsolatedCheck::IsolatedCheck(IsolatedCheck&& o) noexcept
    : mPid(std::exchange(o.mPid, -1))
    , mErrFd(std::exchange(o.mErrFd, -1))
    , mPath(std::move(o.mPath))
    , mReader(std::move(o.mReader))
    , mExpected(std::move(o.mExpected))
    , mLimit(o.mLimit)
    , mT0(o.mT0)
{
}

IsolatedCheck::~IsolatedCheck() { stop(); }

void IsolatedCheck::stop() noexcept
{
    if (mErrFd >= 0) ::close(mErrFd);
    mErrFd = -1;
    if (mPid > 0) {
        int status = 0;
        ::kill(mPid, SIGKILL);
        while (::waitpid(mPid, &status, 0) < 0 && errno == EINTR) {}
    }
    mPid = -1;
}

IsolatedCheck IsolatedCheck::start(const std::string& exe, const std::string& path, const std::vector<std::string>& args,
                                   const std::string& reader, const std::string& expected)
{
    IsolatedCheck c;
    c.mPath = path;
    c.mReader = reader;
    c.mExpected = expected;
    struct stat st{};
    const uint64_t bytes = ::stat(path.c_str(), &st) == 0 ? uint64_t(st.st_size) : 0;
    c.mLimit = readTimeoutSeconds(bytes);

    int errPipe[2];
    if (::pipe2(errPipe, O_CLOEXEC) != 0)
        throw lic::Error(std::string("cannot check ") + quote(path) + " in a child process: pipe failed ("
                         + std::strerror(errno) + ")");
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, errPipe[1], 2);
    std::vector<std::string> env;
    for (char** e = environ; *e; ++e)
        if (std::strncmp(*e, "LICVDB_READ_CHILD=", 18) != 0) env.emplace_back(*e);
    env.emplace_back("LICVDB_READ_CHILD=1");
    std::vector<char*> envp;
    for (auto& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);
    std::vector<std::string> words{exe};
    words.insert(words.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& w : words) argv.push_back(w.data());
    argv.push_back(nullptr);
    pid_t pid = -1;
    const int rc = posix_spawn(&pid, exe.c_str(), &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    ::close(errPipe[1]);
    if (rc != 0) {
        ::close(errPipe[0]);
        throw lic::Error("cannot check " + quote(path) + " in a child process: starting " + quote(exe) + " failed ("
                         + std::strerror(rc) + ")");
    }
    c.mPid = pid;
    c.mErrFd = errPipe[0];
    c.mT0 = std::chrono::steady_clock::now();
    return c;
}

void IsolatedCheck::finish()
{
    if (mPid <= 0) return;
    const std::string& path = mPath;
    const double limit = mLimit;
    const auto t0 = mT0;
    // Collect stderr until the child closes it or the time is up.
    std::string err;
    bool timedOut = false;
    for (;;) {
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (elapsed >= limit) {
            timedOut = true;
            break;
        }
        pollfd pfd{mErrFd, POLLIN, 0};
        const int wait = int(std::min(250.0, (limit - elapsed) * 1000.0)) + 1;
        const int p = ::poll(&pfd, 1, wait);
        if (p < 0 && errno == EINTR) continue;
        if (p <= 0) continue;
        char buf[4096];
        const ssize_t n = ::read(mErrFd, buf, sizeof(buf));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break; // EOF: the child has exited (or closed stderr)
        if (err.size() < 65536) err.append(buf, size_t(n));
    }
    ::close(mErrFd);
    mErrFd = -1;
    if (timedOut) {
        stop();
        throw lic::InputError("reading " + quote(path) + " did not finish within " + std::to_string(int(limit))
                              + " s (in a child process, which was stopped); refused as corrupt; expected " + mExpected
                              + " (set LICVDB_READ_TIMEOUT=SECONDS for a very large file on a slow disk)");
    }
    // stderr is closed; give the child the rest of the time to exit.
    int status = 0;
    for (;;) {
        const pid_t w = ::waitpid(mPid, &status, WNOHANG);
        if (w == mPid) break;
        if (w < 0 && errno != EINTR) {
            mPid = -1;
            throw lic::Error("cannot check " + quote(path) + ": waiting for the child failed");
        }
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (elapsed >= limit) {
            stop();
            throw lic::InputError("reading " + quote(path) + " did not finish within " + std::to_string(int(limit))
                                  + " s (in a child process, which was stopped); refused as corrupt");
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    mPid = -1; // reaped
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        throw lic::InputError("reading " + quote(path) + " crashed " + mReader + " in a child process (signal "
                              + std::to_string(sig) + ": " + strsignal(sig) + "); the file is corrupt; expected " + mExpected);
    }
    const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (code == 0) return;
    if (code == 2) throw lic::InputError(childReason(err));
    throw lic::Error("checking " + quote(path) + " in a child process failed (exit " + std::to_string(code)
                     + "): " + childReason(err));
}

IsolatedCheck startIsolatedCheck(const std::string& path)
{
    std::string exe, helper;
    {
        const std::lock_guard<std::mutex> lock(sExeMutex);
        exe = sExecutable;
        helper = sVdbHelper;
    }
    if (exe.empty()) return {};
    if (!helper.empty())
        return IsolatedCheck::start(helper, path, {"--", path}, "OpenVDB's reader", "an intact OpenVDB .vdb file");
    return IsolatedCheck::start(exe, path, {"info", "--check", "--quiet", "--", path}, "OpenVDB's reader",
                                "an intact OpenVDB .vdb file");
}

void checkInIsolatedProcess(const std::string& path) { startIsolatedCheck(path).finish(); }

void checkReadInIsolatedProcess(const std::string& path, const std::vector<std::string>& args, const std::string& reader,
                                const std::string& expected)
{
    const std::string exe = readIsolationExecutable();
    if (exe.empty()) return;
    IsolatedCheck::start(exe, path, args, reader, expected).finish();
}

} // namespace vdbexport

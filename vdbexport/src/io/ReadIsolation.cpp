// checkInIsolatedProcess(): layer 2 of the read defences (docs/inputs.md). A child process reads
// every grid with OpenVDB; whatever a file does to that reader (a crash, memory corruption, a
// hang) stays in the child, which is killed after a time limit. The child is forked by licvdb's
// fork server where it runs (startReadCheckServer), else started as a program:
// `licvdb-readcheck -- FILE` where it is installed, else `licvdb info --check FILE` with
// LICVDB_READ_CHILD=1 so that it reads in-process.
#include "vdbexport/io/VdbCheck.h"

#include "Quote.h"

#include <lic/util/Error.h>

#include <chrono>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <sys/stat.h>
#include <thread>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace vdbexport {

namespace {

std::mutex sExeMutex;
std::string sExecutable, sVdbHelper;

using detail::q;

/// The child's reason: the text after "error: " on its first error line, else its whole stderr.
std::string childReason(const std::string& err)
{
    const auto at = err.find("error: ");
    std::string line = at == std::string::npos ? err : err.substr(at + 7);
    if (const auto nl = line.find('\n'); nl != std::string::npos) line.resize(nl);
    if (line.size() > 400) line = line.substr(0, 400) + "...";
    return line;
}

// ---- the fork server -----------------------------------------------------------------------
//
// licvdb (P) forks the server (S) at start-up, before any thread of its own. For a check, P sends
// S the path and the write end of a pipe for the child's stderr (SCM_RIGHTS) over a SOCK_SEQPACKET
// pair. S forks an intermediate (I), which forks the child (C) and exits: C, orphaned, is handed to
// P (PR_SET_CHILD_SUBREAPER), and S replies with C's pid once it has reaped I, by which time C is
// P's child. From there P treats C as a started program: reads its stderr, waits, kills on time-out.

constexpr std::size_t kMaxPathBytes = 65536;

struct Server
{
    std::mutex mutex;
    pid_t pid = -1;
    int socket = -1;
};

Server sServer;

/// Send `bytes` as one message (with `passFd`, if any, passed along), retrying on EINTR; false on
/// any failure (the peer gone).
bool sendAll(int fd, const void* data, std::size_t bytes, int passFd = -1)
{
    iovec iov{const_cast<void*>(data), bytes};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int))] = {};
    if (passFd >= 0) {
        msg.msg_control = control;
        msg.msg_controllen = sizeof control;
        cmsghdr* c = CMSG_FIRSTHDR(&msg);
        c->cmsg_level = SOL_SOCKET;
        c->cmsg_type = SCM_RIGHTS;
        c->cmsg_len = CMSG_LEN(sizeof(int));
        std::memcpy(CMSG_DATA(c), &passFd, sizeof(int));
    }
    for (;;) {
        const ssize_t n = ::sendmsg(fd, &msg, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR) continue;
        return n == ssize_t(bytes);
    }
}

/// One message into `buf`; its passed descriptor (close-on-exec) in `passed` (-1 if none).
/// Returns its length, 0 when the peer has gone, -1 on failure.
ssize_t receive(int fd, void* buf, std::size_t size, int* passed = nullptr)
{
    iovec iov{buf, size};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int))] = {};
    msg.msg_control = control;
    msg.msg_controllen = sizeof control;
    ssize_t n = -1;
    do n = ::recvmsg(fd, &msg, MSG_CMSG_CLOEXEC);
    while (n < 0 && errno == EINTR);
    if (passed) *passed = -1;
    for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c))
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_RIGHTS) {
            int got = -1;
            std::memcpy(&got, CMSG_DATA(c), sizeof(int));
            if (passed) *passed = got;
            else ::close(got);
        }
    if (n >= 0 && (msg.msg_flags & (MSG_TRUNC | MSG_CTRUNC))) return -1;
    return n;
}

void redirectToNull(int target, int flags)
{
    const int fd = ::open("/dev/null", flags | O_CLOEXEC);
    if (fd >= 0 && fd != target) {
        ::dup2(fd, target);
        ::close(fd);
    }
}

/// The server's loop: one child per request, until P closes its end. Never returns.
[[noreturn]] void serve(int sock, const std::function<int(const std::string&)>& check)
{
    redirectToNull(0, O_RDONLY);
    redirectToNull(1, O_WRONLY);
    redirectToNull(2, O_WRONLY);
    ::signal(SIGINT, SIG_IGN); // Ctrl-C is P's to handle (a cancelled bake stops its checks)
    std::vector<char> buf(kMaxPathBytes);
    for (;;) {
        int errFd = -1;
        const ssize_t n = receive(sock, buf.data(), buf.size(), &errFd);
        if (n <= 0) ::_exit(0); // P has gone (or the channel broke): nothing left to serve
        const std::string path(buf.data(), std::size_t(n));
        std::int64_t reply = -EINVAL;
        int pidPipe[2] = {-1, -1};
        if (errFd >= 0 && ::pipe2(pidPipe, O_CLOEXEC) == 0) {
            const pid_t mid = ::fork();
            if (mid == 0) {
                ::close(pidPipe[0]);
                const pid_t child = ::fork();
                if (child == 0) {
                    ::close(sock);
                    ::close(pidPipe[1]);
                    ::signal(SIGINT, SIG_DFL);
                    ::dup2(errFd, 2);
                    ::close(errFd);
                    setReadIsolation(""); // the child reads in-process: no check of its own
                    ::_exit(check(path));
                }
                const std::int64_t v = child > 0 ? std::int64_t(child) : -std::int64_t(errno);
                (void)!::write(pidPipe[1], &v, sizeof v);
                ::_exit(0);
            }
            ::close(pidPipe[1]);
            if (mid < 0) {
                reply = -std::int64_t(errno);
            } else {
                std::int64_t v = 0;
                ssize_t got = -1;
                do got = ::read(pidPipe[0], &v, sizeof v);
                while (got < 0 && errno == EINTR);
                reply = got == ssize_t(sizeof v) ? v : -EIO;
                int status = 0;
                while (::waitpid(mid, &status, 0) < 0 && errno == EINTR) {}
            }
            ::close(pidPipe[0]);
        }
        if (errFd >= 0) ::close(errFd);
        if (!sendAll(sock, &reply, sizeof reply)) ::_exit(0);
    }
}

/// Start a check through the server; nullopt if there is none or it has gone (the caller starts
/// a program instead).
std::optional<IsolatedCheck> startServedCheck(const std::string& path, const std::string& reader,
                                              const std::string& expected)
{
    if (path.empty() || path.size() > kMaxPathBytes) return std::nullopt;
    const std::lock_guard<std::mutex> lock(sServer.mutex);
    if (sServer.socket < 0) return std::nullopt;
    int errPipe[2];
    if (::pipe2(errPipe, O_CLOEXEC) != 0) return std::nullopt;
    std::int64_t reply = 0;
    const bool sent = sendAll(sServer.socket, path.data(), path.size(), errPipe[1]);
    ::close(errPipe[1]);
    const ssize_t n = sent ? receive(sServer.socket, &reply, sizeof reply) : -1;
    if (n != ssize_t(sizeof reply) || reply <= 0) {
        ::close(errPipe[0]);
        if (n != ssize_t(sizeof reply)) { // the server has gone: stop using it
            ::close(sServer.socket);
            sServer.socket = -1;
        }
        return std::nullopt;
    }
    return IsolatedCheck::adopt(pid_t(reply), errPipe[0], path, reader, expected);
}

} // namespace

bool startReadCheckServer(std::function<int(const std::string& path)> check)
{
    const std::lock_guard<std::mutex> lock(sServer.mutex);
    if (sServer.socket >= 0) return true;
    // The server's children are handed to this process when their parent exits.
    if (::prctl(PR_SET_CHILD_SUBREAPER, 1) != 0) return false;
    int pair[2];
    if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, pair) != 0) return false;
    const pid_t pid = ::fork();
    if (pid < 0) {
        ::close(pair[0]);
        ::close(pair[1]);
        return false;
    }
    if (pid == 0) {
        ::close(pair[0]);
        serve(pair[1], check);
    }
    ::close(pair[1]);
    sServer.pid = pid;
    sServer.socket = pair[0];
    // At exit the server is told to end (EOF) and waited for: nothing of licvdb's outlives it.
    static const bool registered = std::atexit([] { stopReadCheckServer(); }) == 0;
    (void)registered;
    return true;
}

void stopReadCheckServer()
{
    const std::lock_guard<std::mutex> lock(sServer.mutex);
    if (sServer.socket >= 0) ::close(sServer.socket); // the server exits on EOF
    sServer.socket = -1;
    if (sServer.pid > 0) {
        int status = 0;
        while (::waitpid(sServer.pid, &status, 0) < 0 && errno == EINTR) {}
    }
    sServer.pid = -1;
}

pid_t readCheckServerPid()
{
    const std::lock_guard<std::mutex> lock(sServer.mutex);
    return sServer.socket >= 0 ? sServer.pid : -1;
}

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

IsolatedCheck IsolatedCheck::adopt(pid_t pid, int errFd, const std::string& path, const std::string& reader,
                                   const std::string& expected)
{
    IsolatedCheck c;
    c.mPath = path;
    c.mReader = reader;
    c.mExpected = expected;
    struct stat st{};
    const uint64_t bytes = ::stat(path.c_str(), &st) == 0 ? uint64_t(st.st_size) : 0;
    c.mLimit = readTimeoutSeconds(bytes);
    c.mPid = pid;
    c.mErrFd = errFd;
    c.mT0 = std::chrono::steady_clock::now();
    return c;
}

IsolatedCheck IsolatedCheck::start(const std::string& exe, const std::string& path, const std::vector<std::string>& args,
                                   const std::string& reader, const std::string& expected)
{
    int errPipe[2];
    if (::pipe2(errPipe, O_CLOEXEC) != 0)
        throw lic::Error(std::string("cannot check ") + q(path) + " in a child process: pipe failed ("
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
        throw lic::Error("cannot check " + q(path) + " in a child process: starting " + q(exe) + " failed ("
                         + std::strerror(rc) + ")");
    }
    return adopt(pid, errPipe[0], path, reader, expected);
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
        throw lic::InputError("reading " + q(path) + " did not finish within " + std::to_string(int(limit))
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
            throw lic::Error("cannot check " + q(path) + ": waiting for the child failed");
        }
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (elapsed >= limit) {
            stop();
            throw lic::InputError("reading " + q(path) + " did not finish within " + std::to_string(int(limit))
                                  + " s (in a child process, which was stopped); refused as corrupt");
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    mPid = -1; // reaped
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        throw lic::InputError("reading " + q(path) + " crashed " + mReader + " in a child process (signal "
                              + std::to_string(sig) + ": " + strsignal(sig) + "); the file is corrupt; expected " + mExpected);
    }
    const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (code == 0) return;
    if (code == 2) throw lic::InputError(childReason(err));
    throw lic::Error("checking " + q(path) + " in a child process failed (exit " + std::to_string(code)
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
    if (auto served = startServedCheck(path, "OpenVDB's reader", "an intact OpenVDB .vdb file"))
        return std::move(*served);
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

// Atomic writes (AtomicWrite.h): the checks before writing, the temporaries a killed process left,
// the flush and rename; writeVdbAtomic and writeTextAtomic are OutputSets of one file.
#include "vdbexport/io/AtomicWrite.h"

#include "vdbexport/io/OutputSet.h"
#include "Quote.h"

#include <lic/util/Error.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <system_error>

#include <fcntl.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbexport {

namespace detail {

/// Check that `path` names a file we may create: its directory exists and is writable, and
/// `path` itself is not a directory. Returns the temporary name to write first.
std::string prepareAtomicWrite(const std::string& path)
{
    if (path.empty()) throw lic::InputError("cannot write a file with an empty path; expected a file name");
    const fs::path p(path);
    fs::path dir = p.parent_path();
    if (dir.empty()) dir = ".";
    std::error_code ec;
    if (!fs::exists(dir, ec))
        throw lic::InputError("cannot write " + q(path) + ": directory " + q(dir.string())
                              + " does not exist; create it first or choose another output path");
    if (!fs::is_directory(dir, ec))
        throw lic::InputError("cannot write " + q(path) + ": " + q(dir.string())
                              + " is not a directory; expected an existing directory");
    if (::access(dir.c_str(), W_OK) != 0)
        throw lic::InputError("cannot write " + q(path) + ": directory " + q(dir.string())
                              + " is not writable (" + std::strerror(errno) + ")");
    if (fs::is_directory(p, ec))
        throw lic::InputError("cannot write " + q(path)
                              + ": it is a directory; expected a file path");
    removeStaleTemporaries(path);
    return path + ".tmp-" + std::to_string(::getpid());
}

void removeStaleTemporaries(const std::string& path)
{
    // PATH.tmp-PID (a named temporary) and PATH.tmp-PID-N (a commit's link, renamed a moment
    // later) of a process that no longer exists: what a process killed (SIGKILL cannot be
    // caught) while writing PATH left behind.
    const fs::path p(path);
    fs::path dir = p.parent_path();
    if (dir.empty()) dir = ".";
    const std::string prefix = p.filename().string() + ".tmp-";
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.rfind(prefix, 0) != 0) continue;
        const std::string rest = name.substr(prefix.size());
        const std::size_t digits = rest.find_first_not_of("0123456789");
        if (digits == 0 || (digits != std::string::npos && rest[digits] != '-')) continue;
        const long pid = std::strtol(rest.c_str(), nullptr, 10);
        if (pid <= 0 || pid == long(::getpid())) continue;
        if (::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue; // alive (or not ours to judge)
        std::error_code rm;
        fs::remove(it->path(), rm);
    }
}

/// Flush `tmp` to disk, then rename it over `path`. Removes `tmp` and throws lic::Error on failure.
void commitAtomicWrite(const std::string& tmp, const std::string& path)
{
    std::error_code ec;
    const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || ::fsync(fd) != 0) {
        const std::string reason = std::strerror(errno);
        if (fd >= 0) ::close(fd);
        fs::remove(tmp, ec);
        throw lic::Error("cannot write " + q(path) + ": flushing " + q(tmp) + " failed ("
                         + reason + ")");
    }
    ::close(fd);
    fs::rename(tmp, path, ec);
    if (ec) {
        const std::string reason = ec.message();
        fs::remove(tmp, ec);
        throw lic::Error("cannot write " + q(path) + ": renaming " + q(tmp) + " failed ("
                         + reason + ")");
    }
}

bool noTmpfile()
{
    const char* v = std::getenv("LICVDB_TEST_NO_O_TMPFILE");
    return v && std::string(v) == "1";
}

} // namespace detail

void writeVdbAtomic(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata)
{
    OutputSet out;
    out.addVdb(path, std::move(grids), fileMetadata);
    out.commit();
}

void writeTextAtomic(const std::string& path, const std::string& text)
{
    OutputSet out;
    out.addText(path, text);
    out.commit();
}

} // namespace vdbexport

// OutputSet (OutputSet.h): files staged in unseen temporaries (O_TMPFILE, else named), checked,
// flushed and hashed, then linked and renamed into place together under a directory lock; and the
// test seams that stop or kill a commit part-way.
#include "vdbexport/io/OutputSet.h"

#include "vdbexport/io/AtomicWrite.h"
#include "vdbexport/io/Sha256.h"
#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/VdbWrite.h"
#include "Quote.h"

#include <lic/util/Error.h>

#include <openvdb/io/File.h>

#include <tbb/parallel_invoke.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <set>
#include <system_error>
#include <thread>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbexport {

namespace {

using detail::q;

/// The grid types whose tiles writeVdbAtomic voxelizes (point grids are left alone).
using VoxelizableGridTypes = openvdb::NumericGridTypes::Append<openvdb::Vec3GridTypes>::Append<
    openvdb::BoolGrid, openvdb::MaskGrid>;

std::string fdPath(int fd) { return "/proc/self/fd/" + std::to_string(fd); }

} // namespace

namespace detail {

namespace {

/// Test seam, read only by tests: $LICVDB_TEST_COMMIT_HOOK = "POINT ACTION". POINT is `staged`
/// (every file staged, none linked, the lock not yet taken), `locked` (the lock held, none linked)
/// or `linked:N` (N files renamed into place, in the order added: a bake's frames, then its
/// manifest). ACTION is `kill` (SIGKILL to this process), `stop` (SIGSTOP: the test inspects the
/// disk, then continues or kills it) or `touch:FILE` (create FILE, then go on).
void commitHook(const std::string& point)
{
    static const char* spec = std::getenv("LICVDB_TEST_COMMIT_HOOK");
    if (!spec) return;
    const std::string s(spec);
    const std::size_t space = s.find(' ');
    if (space == std::string::npos || s.substr(0, space) != point) return;
    const std::string action = s.substr(space + 1);
    if (action == "kill") ::kill(::getpid(), SIGKILL);
    else if (action == "stop") ::kill(::getpid(), SIGSTOP);
    else if (action.rfind("touch:", 0) == 0) std::ofstream(action.substr(6)).put('\n');
}

} // namespace

} // namespace detail

OutputSet::~OutputSet()
{
    for (auto& f : mFiles) discard(f);
}

void OutputSet::discard(Staged& f)
{
    if (f.fd >= 0) ::close(f.fd);
    f.fd = -1;
    if (!f.named.empty()) {
        std::error_code ec;
        fs::remove(f.named, ec);
        f.named.clear();
    }
}

void OutputSet::refuseTwice(const std::string& path) const
{
    for (const auto& f : mFiles)
        if (f.path == path) throw lic::Error("cannot write " + q(path) + " twice in one output set");
}

OutputSet::Staged OutputSet::stage(const std::string& path)
{
    Staged f;
    f.path = path;
    const std::string named = detail::prepareAtomicWrite(path);
    fs::path dir = fs::path(path).parent_path();
    if (dir.empty()) dir = ".";
    // An unnamed file in the target directory: a process killed before commit() leaves nothing.
    f.fd = detail::noTmpfile() ? -1 : ::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0666);
    if (f.fd < 0) f.named = named; // no O_TMPFILE on this file system: a named temporary
    return f;
}

std::string OutputSet::target(const Staged& f) { return f.fd >= 0 ? fdPath(f.fd) : f.named; }

void OutputSet::finish(Staged& f)
{
    const int fd = f.fd >= 0 ? f.fd : ::open(f.named.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        const std::string reason = std::strerror(errno);
        throw lic::Error("cannot write " + q(f.path) + ": flushing it failed (" + reason + ")");
    }
    // fsync waits on the disk, not on a core (41 ms for the figure-12 file here): it runs on a
    // thread of its own while this one hashes the same bytes from the page cache.
    int syncError = 0;
    std::exception_ptr hashFailed;
    {
        std::jthread flusher([&] { syncError = ::fsync(fd) == 0 ? 0 : errno; });
        try {
            f.sha256 = sha256OfFd(fd);
        } catch (...) {
            hashFailed = std::current_exception();
        }
    }
    if (fd != f.fd) ::close(fd);
    if (syncError != 0)
        throw lic::Error("cannot write " + q(f.path) + ": flushing it failed (" + std::strerror(syncError) + ")");
    if (hashFailed) std::rethrow_exception(hashFailed);
}

void OutputSet::addVdb(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata,
                       const detail::SealedLeaves* sealed)
{
    refuseTwice(path);
    add(writeVdb(path, std::move(grids), fileMetadata, sealed));
}

void OutputSet::add(Pending&& file)
{
    refuseTwice(file.mFile.path);
    mFiles.push_back(std::move(file.mFile));
    file.mFile.fd = -1;
    file.mFile.named.clear();
}

namespace {

/// The structure of the file written at `tmp` (for `path`), and its grids' headers read back.
void checkWritten(const std::string& path, const std::string& tmp, std::size_t gridCount)
{
    try {
        checkVdbStructure(tmp, VdbCheckDepth::Layout);
    } catch (const lic::InputError& e) {
        throw lic::Error("cannot write " + q(path) + ": the file written is incomplete (disk full?): "
                         + e.what());
    }
    openvdb::io::File check(tmp);
    check.open(/*delayLoad=*/false);
    const auto written = check.readAllGridMetadata();
    check.close();
    if (!written || written->size() != gridCount)
        throw lic::Error("cannot write " + q(path) + ": only " + std::to_string(written ? written->size() : 0)
                         + " of " + std::to_string(gridCount) + " grids could be read back");
}

} // namespace

OutputSet::Pending OutputSet::writeVdb(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata,
                                      const detail::SealedLeaves* sealed)
{
    openvdb::initialize();
    Staged f = stage(path);
    const std::string tmp = target(f);
    try {
        for (std::size_t i = 0; i < grids.size(); ++i) {
            if (!grids[i])
                throw lic::Error("cannot write " + q(path) + ": grid #" + std::to_string(i)
                                 + " is null; expected a grid");
            if (grids[i]->baseTree().activeTileCount() == 0) continue;
            // Voxelize a copy: the caller's grid keeps its (cheaper) tiles.
            auto copy = grids[i]->deepCopyGrid();
            copy->apply<VoxelizableGridTypes>([](auto& grid) { grid.tree().voxelizeActiveTiles(); });
            grids[i] = copy;
        }
        detail::writeVdbFile(tmp, openvdb::GridCPtrVec(grids.begin(), grids.end()), fileMetadata, detail::kWriteHoldBytes,
                             sealed);
        // io::File does not report stream errors after opening (e.g. a full disk): check the
        // structure of what was written and read the headers back. Beside it, the file is flushed
        // and hashed (finish); a failed check is reported first.
        std::exception_ptr checkFailed, finishFailed;
        const auto keeping = [](std::exception_ptr& failed, auto work) {
            return [&failed, work] {
                try {
                    work();
                } catch (...) {
                    failed = std::current_exception();
                }
            };
        };
        tbb::parallel_invoke(keeping(checkFailed, [&] { checkWritten(path, tmp, grids.size()); }),
                             keeping(finishFailed, [&] { finish(f); }));
        if (checkFailed) std::rethrow_exception(checkFailed);
        if (finishFailed) std::rethrow_exception(finishFailed);
    } catch (const lic::Error&) {
        discard(f);
        throw;
    } catch (const std::exception& e) {
        discard(f);
        throw lic::Error("cannot write " + q(path) + ": " + e.what());
    }
    return Pending(std::move(f));
}

void OutputSet::addText(const std::string& path, const std::string& text)
{
    refuseTwice(path);
    Staged f = stage(path);
    try {
        std::ofstream out(target(f), std::ios::binary | std::ios::trunc);
        if (out) out.write(text.data(), static_cast<std::streamsize>(text.size()));
        if (out) out.flush();
        if (!out) throw lic::Error("cannot write " + q(path) + " (" + std::strerror(errno) + ")");
        out.close();
        finish(f);
    } catch (...) {
        discard(f);
        throw;
    }
    mFiles.push_back(std::move(f));
}

std::string OutputSet::sha256(const std::string& path) const
{
    for (const auto& f : mFiles)
        if (f.path == path) return f.sha256;
    throw lic::Error("no file " + q(path) + " in this output set");
}

void OutputSet::commit()
{
    // One exclusive lock per target directory, taken in a fixed order, held while the files
    // are renamed into place: two bakes committing to the same place cannot interleave.
    std::set<std::string> dirs;
    for (const auto& f : mFiles) {
        const fs::path d = fs::path(f.path).parent_path();
        dirs.insert(d.empty() ? "." : d.string());
    }
    detail::commitHook("staged");
    std::vector<int> locks;
    const auto unlock = [&] {
        for (const int fd : locks) ::close(fd); // closing releases the flock
        locks.clear();
    };
    for (const auto& d : dirs) {
        const int fd = ::open(d.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (fd < 0) continue;
        while (::flock(fd, LOCK_EX) != 0 && errno == EINTR) {}
        locks.push_back(fd); // a file system without flock: commit unlocked (the checksums still tell)
    }
    try {
        detail::commitHook("locked");
        int n = 0;
        for (auto& f : mFiles) {
            std::error_code ec;
            if (f.fd >= 0) {
                const std::string link = f.path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(n++);
                fs::remove(link, ec);
                if (::linkat(AT_FDCWD, fdPath(f.fd).c_str(), AT_FDCWD, link.c_str(), AT_SYMLINK_FOLLOW) != 0)
                    throw lic::Error("cannot write " + q(f.path) + ": linking its data failed (" + std::strerror(errno) + ")");
                fs::rename(link, f.path, ec);
                if (ec) {
                    std::error_code ec2;
                    fs::remove(link, ec2);
                    throw lic::Error("cannot write " + q(f.path) + ": renaming failed (" + ec.message() + ")");
                }
                ::close(f.fd);
                f.fd = -1;
            } else {
                fs::rename(f.named, f.path, ec);
                if (ec) throw lic::Error("cannot write " + q(f.path) + ": renaming " + q(f.named) + " failed (" + ec.message() + ")");
                f.named.clear();
            }
            detail::commitHook("linked:" + std::to_string(&f - mFiles.data() + 1));
        }
    } catch (...) {
        unlock();
        throw;
    }
    for (const int fd : locks) ::fsync(fd); // the renames themselves
    unlock();
    mFiles.clear();
}

} // namespace vdbexport

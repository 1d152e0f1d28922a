#include "vdbexport/io/VdbIO.h"

#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/Sha256.h"
#include "Quote.h"
#include "VdbGridReader.h"

#include <lic/util/Error.h>

#include <openvdb/Exceptions.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/ValueTransformer.h>
#include <openvdb/tree/LeafManager.h>

#include <log4cplus/logger.h>

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <new>
#include <set>
#include <sstream>
#include <system_error>
#include <thread>
#include <tuple>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbexport {

namespace {

using detail::q;

std::string cleanMessage(const char* what);

/// Run `fn`, turning any exception other than lic::Error into a lic::InputError that names
/// the file and what was being done (OpenVDB reports corrupt and truncated files as IoError,
/// RuntimeError, KeyError, … and sometimes as std::exception).
template<typename Fn>
auto guardRead(const std::string& path, const char* what, Fn&& fn) -> decltype(fn())
{
    try {
        return fn();
    } catch (const lic::Error&) {
        throw;
    } catch (const std::exception& e) { // openvdb::Exception is a std::exception
        throw lic::InputError("cannot read " + q(path) + " (" + what + "): " + cleanMessage(e.what())
                              + "; expected an intact OpenVDB .vdb file (corrupt or truncated?)");
    }
}

/// Copy name, class, metadata and transform of `src` onto `dst`.
void copyGridAttributes(const openvdb::GridBase& src, openvdb::GridBase& dst)
{
    static_cast<openvdb::MetaMap&>(dst) = static_cast<const openvdb::MetaMap&>(src);
    dst.setTransform(src.constTransform().copy());
}

/// A value converted to another value type (double → float, Vec3d → Vec3s, Vec3i → Vec3s).
/// OpenVDB's value-converting tree constructor refuses Vec3d → Vec3s, so convert by hand.
template<typename DstV, typename SrcV>
DstV convertValue(const SrcV& v)
{
    if constexpr (openvdb::VecTraits<SrcV>::IsVec) {
        using E = typename openvdb::VecTraits<DstV>::ElementType;
        return DstV(static_cast<E>(v[0]), static_cast<E>(v[1]), static_cast<E>(v[2]));
    } else {
        return static_cast<DstV>(v);
    }
}

/// A copy of `src` with another value type: same topology, every voxel and tile value (active
/// or not) converted, and the same name, class, metadata and transform.
template<typename DstGridT, typename SrcGridT>
typename DstGridT::Ptr convertGrid(const SrcGridT& src)
{
    using DstTreeT = typename DstGridT::TreeType;
    using DstV = typename DstGridT::ValueType;
    auto tree = std::make_shared<DstTreeT>(src.tree(), convertValue<DstV>(src.background()),
                                           openvdb::TopologyCopy());
    // Leaf voxels, in parallel.
    openvdb::tree::LeafManager<DstTreeT> leaves(*tree);
    leaves.foreach([&](typename DstTreeT::LeafNodeType& leaf, std::size_t) {
        const auto* srcLeaf = src.tree().probeConstLeaf(leaf.origin());
        if (!srcLeaf) return;
        for (openvdb::Index i = 0; i < DstTreeT::LeafNodeType::SIZE; ++i)
            leaf.setValueOnly(i, convertValue<DstV>(srcLeaf->getValue(i)));
    });
    // Tiles of the root and internal nodes.
    auto srcAcc = src.getConstAccessor();
    auto it = tree->beginValueAll();
    it.setMaxDepth(DstTreeT::RootNodeType::LEVEL - 1);
    for (; it; ++it) it.setValue(convertValue<DstV>(srcAcc.getValue(it.getCoord())));

    auto dst = DstGridT::create(tree);
    copyGridAttributes(src, *dst);
    return dst;
}

/// An exception message fit to quote: control characters and runs of blanks collapsed (OpenVDB
/// echoes garbage read from damaged files), at most 200 characters.
std::string cleanMessage(const char* what)
{
    std::string out;
    for (const char* c = what; *c && out.size() < 200; ++c) {
        const bool blank = std::isspace(static_cast<unsigned char>(*c)) || std::iscntrl(static_cast<unsigned char>(*c));
        if (blank && (out.empty() || out.back() == ' ')) continue;
        out.push_back(blank ? ' ' : *c);
    }
    if (out.size() >= 200) out += "...";
    return out;
}

openvdb::Vec3SGrid::Ptr toVec3S(const openvdb::GridBase::Ptr& grid)
{
    if (auto g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(grid)) return g;
    if (auto g = openvdb::gridConstPtrCast<openvdb::Vec3DGrid>(grid))
        return convertGrid<openvdb::Vec3SGrid>(*g);
    if (auto g = openvdb::gridConstPtrCast<openvdb::Vec3IGrid>(grid))
        return convertGrid<openvdb::Vec3SGrid>(*g);
    return nullptr;
}

openvdb::FloatGrid::Ptr toFloat(const openvdb::GridBase::Ptr& grid)
{
    if (auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(grid)) return g;
    if (auto g = openvdb::gridConstPtrCast<openvdb::DoubleGrid>(grid))
        return convertGrid<openvdb::FloatGrid>(*g);
    return nullptr;
}

/// The grid types whose tiles writeVdbAtomic voxelizes (point grids are left alone).
using VoxelizableGridTypes = openvdb::NumericGridTypes::Append<openvdb::Vec3GridTypes>::Append<
    openvdb::BoolGrid, openvdb::MaskGrid>;

} // namespace

// ------------------------------------------------------------------------------------------
// detail

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

/// Test seam: $LICVDB_TEST_NO_O_TMPFILE=1 stages named temporaries, as on a file system without
/// O_TMPFILE.
bool noTmpfile()
{
    static const bool off = [] {
        const char* v = std::getenv("LICVDB_TEST_NO_O_TMPFILE");
        return v && std::string(v) == "1";
    }();
    return off;
}

} // namespace

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


VdbReader::VdbReader(std::string path) : mPath(std::move(path))
{
    openvdb::initialize();
    try {
        // The path itself (none, missing, a directory, empty, unreadable) first: the check's
        // rules no-path, not-found, directory, empty and open, with their marker.
        mCheck = checkedVdb(mPath);
    } catch (const lic::Error&) {
        throw;
    } catch (const std::exception& e) {
        throw lic::InputError("cannot read " + q(mPath) + ": " + cleanMessage(e.what()));
    }
    mFile = std::make_unique<openvdb::io::File>(mPath);
    try {
        const QuietNewerFormat quiet(mCheck.fileVersion);
        mFile->open(/*delayLoad=*/false);
        // Grids are read through a stream that costs fewer system calls (VdbGridReader.h); files
        // without grid offsets only io::File reads.
        mGrids = std::make_unique<GridFileReader>(mPath);
        if (!mGrids->random()) mGrids.reset();
    } catch (const std::exception& e) {
        const std::string msg = cleanMessage(e.what());
        if (msg.find("not a VDB file") != std::string::npos)
            throw lic::InputError(q(mPath) + " is not an OpenVDB file (no VDB header); "
                                  "expected a .vdb file");
        throw lic::InputError("cannot open " + q(mPath) + " as a .vdb file: " + msg
                              + "; expected an intact OpenVDB .vdb file (corrupt or truncated?)");
    }
}

VdbReader::~VdbReader()
{
    try {
        if (mFile && mFile->isOpen()) mFile->close();
    } catch (...) {
    }
}

std::vector<std::pair<std::string, std::string>> VdbReader::gridTypes()
{
    return guardRead(mPath, "reading grid headers", [&] {
        std::vector<std::pair<std::string, std::string>> out;
        const auto grids = mFile->readAllGridMetadata();
        for (const auto& g : *grids) out.emplace_back(g->getName(), g->valueType());
        return out;
    });
}

openvdb::GridBase::Ptr VdbReader::readGrid(const std::string& name)
{
    const std::string what = "reading grid " + q(name);
    return guardRead(mPath, what.c_str(), [&] {
        for (const auto& g : mCheck.grids)
            if (g.name == name && !g.skipReason.empty())
                throw lic::InputError("grid " + q(name) + " in " + q(mPath) + " (" + g.gridType
                                      + ") cannot be read: " + g.skipReason);
        if (!mFile->hasGrid(name))
            throw lic::InputError("grid " + q(name) + " not found in " + q(mPath)
                                  + "; the file has: " + listGrids(gridTypes()));
        auto grid = mGrids ? mGrids->readGrid(name) : mFile->readGrid(name);
        if (!grid) throw lic::InputError("grid " + q(name) + " in " + q(mPath) + " could not be read");
        return grid;
    });
}

openvdb::GridPtrVec VdbReader::readAllGrids()
{
    return guardRead(mPath, "reading grids", [&] {
        const bool skipped = std::any_of(mCheck.grids.begin(), mCheck.grids.end(),
                                         [](const VdbGridCheck& g) { return !g.skipReason.empty(); });
        if (!skipped && mGrids) return mGrids->readAllGrids();
        if (!skipped) {
            const auto grids = mFile->getGrids();
            return grids ? *grids : openvdb::GridPtrVec{};
        }
        openvdb::GridPtrVec grids; // grids of types licvdb does not read are left out
        for (const auto& g : mCheck.grids)
            if (g.skipReason.empty()) grids.push_back(mGrids ? mGrids->readGrid(g.name) : mFile->readGrid(g.name));
        return grids;
    });
}

openvdb::MetaMap::Ptr VdbReader::fileMetadata()
{
    return guardRead(mPath, "reading file metadata", [&] {
        auto meta = mFile->getMetadata();
        return meta ? meta : std::make_shared<openvdb::MetaMap>();
    });
}

namespace {

/// Files that passed checkedVdb, keyed by what identifies an unchanged file.
struct FileKey
{
    dev_t dev;
    ino_t ino;
    off_t size;
    int64_t mtimeNs;
    bool operator<(const FileKey& o) const
    {
        return std::tie(dev, ino, size, mtimeNs) < std::tie(o.dev, o.ino, o.size, o.mtimeNs);
    }
};

std::mutex sCheckedMutex;
std::map<FileKey, VdbCheckResult> sChecked;

bool fileKey(const std::string& path, FileKey& key)
{
    struct stat st{};
    if (::stat(path.c_str(), &st) != 0) return false;
    key = {st.st_dev, st.st_ino, st.st_size, int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec};
    return true;
}

} // namespace

namespace {
std::mutex sQuietMutex;
int sQuietScopes = 0;
log4cplus::LogLevel sQuietSaved = log4cplus::NOT_SET_LOG_LEVEL;
/// OpenVDB's logger (openvdb/util/logging.h getLogger(): its headers use it only where the
/// program defines OPENVDB_USE_LOG4CPLUS, so licvdb names it itself).
log4cplus::Logger openvdbLogger() { return log4cplus::Logger::getInstance(LOG4CPLUS_TEXT("openvdb")); }
} // namespace

QuietNewerFormat::QuietNewerFormat(uint32_t fileVersion) : mActive(fileVersion > openvdb::OPENVDB_FILE_VERSION)
{
    if (!mActive) return;
    const std::lock_guard<std::mutex> lock(sQuietMutex);
    if (sQuietScopes++ == 0) {
        log4cplus::Logger logger = openvdbLogger();
        sQuietSaved = logger.getLogLevel();
        logger.setLogLevel(std::max(sQuietSaved, log4cplus::ERROR_LOG_LEVEL));
    }
}

QuietNewerFormat::~QuietNewerFormat()
{
    if (!mActive) return;
    const std::lock_guard<std::mutex> lock(sQuietMutex);
    if (--sQuietScopes == 0) openvdbLogger().setLogLevel(sQuietSaved);
}

VdbCheckResult checkedVdb(const std::string& path)
{
    FileKey before{};
    const bool known = fileKey(path, before);
    if (known) {
        const std::lock_guard<std::mutex> lock(sCheckedMutex);
        if (const auto it = sChecked.find(before); it != sChecked.end()) return it->second;
    }
    // The child (which runs layer 1 itself before reading) works beside this process's layer 1;
    // if layer 1 refuses the file here, the child is stopped and that message is the one given.
    IsolatedCheck child = startIsolatedCheck(path);
    VdbCheckResult result = checkVdbStructure(path);
    child.finish();
    FileKey after{};
    if (known && fileKey(path, after) && !(before < after) && !(after < before)) {
        const std::lock_guard<std::mutex> lock(sCheckedMutex);
        sChecked[after] = result;
    }
    return result;
}

void clearCheckedVdbCache()
{
    const std::lock_guard<std::mutex> lock(sCheckedMutex);
    sChecked.clear();
}

int readCheckMain(const std::string& path, const char* who)
{
    try {
        openvdb::initialize();
        // VdbReader runs layer 1 first (checkedVdb), then what licvdb's reads do with the file.
        // (`licvdb info` describes grids already read: nothing of the file's is left to check.)
        VdbReader reader(path);
        (void)reader.fileMetadata();
        (void)reader.gridTypes();
        (void)reader.readAllGrids();
        return 0;
    } catch (const lic::InputError& e) {
        std::cerr << who << ": error: " << e.what() << "\n";
        return 2;
    } catch (const std::bad_alloc&) {
        std::cerr << who << ": error: out of memory\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << who << ": error: " << e.what() << "\n";
        return 1;
    }
}

std::string listGrids(const std::vector<std::pair<std::string, std::string>>& grids)
{
    if (grids.empty()) return "no grids";
    std::string s;
    for (const auto& [name, type] : grids) {
        if (!s.empty()) s += ", ";
        s += (name.empty() ? std::string("(unnamed)") : name) + " (" + type + ")";
    }
    return s;
}

bool isVec3Type(const std::string& valueType)
{
    return valueType == openvdb::typeNameAsString<openvdb::Vec3s>()
        || valueType == openvdb::typeNameAsString<openvdb::Vec3d>()
        || valueType == openvdb::typeNameAsString<openvdb::Vec3i>();
}

} // namespace detail

// ------------------------------------------------------------------------------------------
// reading

namespace {

bool isScalarType(const std::string& t)
{
    return t == openvdb::typeNameAsString<float>() || t == openvdb::typeNameAsString<double>();
}

/// The base name `b` for which `b.x`, `b.y`, `b.z` (or `b_x`…) are all scalar grids of the file,
/// preferring `velocity`, `vel`, `v`; "" if there is none. `sep` receives the separator.
std::string findSplitBase(const std::vector<std::pair<std::string, std::string>>& grids, const std::string& only,
                          std::string& sep)
{
    const auto has = [&](const std::string& n) {
        return std::any_of(grids.begin(), grids.end(), [&](const auto& g) { return g.first == n && isScalarType(g.second); });
    };
    std::vector<std::string> candidates;
    if (!only.empty()) candidates.push_back(only);
    else {
        for (const char* n : kDefaultVelocityNames) candidates.emplace_back(n);
        for (const auto& g : grids)
            if (g.first.size() > 2 && (g.first.compare(g.first.size() - 2, 2, ".x") == 0 || g.first.compare(g.first.size() - 2, 2, "_x") == 0))
                candidates.push_back(g.first.substr(0, g.first.size() - 2));
    }
    for (const auto& b : candidates)
        for (const char* sp : {".", "_"})
            if (has(b + sp + "x") && has(b + sp + "y") && has(b + sp + "z")) {
                sep = sp;
                return b;
            }
    return "";
}

/// For a base name with some but not all of its split components (`vel.x`, `vel.y` without
/// `vel.z`): " (split components 'vel.x', 'vel.y' found, 'vel.z' missing)"; "" otherwise.
/// `only` = "" looks at the default names (velocity, vel, v) and every `*.x`/`*_x` grid.
std::string partialSplitNote(const std::vector<std::pair<std::string, std::string>>& grids, const std::string& only)
{
    const auto has = [&](const std::string& n) {
        return std::any_of(grids.begin(), grids.end(), [&](const auto& g) { return g.first == n && isScalarType(g.second); });
    };
    std::vector<std::string> bases;
    if (!only.empty()) bases.push_back(only);
    else {
        for (const char* n : kDefaultVelocityNames) bases.emplace_back(n);
        for (const auto& g : grids)
            if (g.first.size() > 2 && (g.first[g.first.size() - 2] == '.' || g.first[g.first.size() - 2] == '_'))
                bases.push_back(g.first.substr(0, g.first.size() - 2));
    }
    for (const auto& b : bases)
        for (const char* sp : {".", "_"}) {
            std::string found, missing;
            for (const char a : {'x', 'y', 'z'}) {
                const std::string n = b + sp + a;
                std::string& list = has(n) ? found : missing;
                list += (list.empty() ? "" : ", ") + q(n);
            }
            if (!found.empty() && !missing.empty())
                return " (split components " + found + " found, " + missing + " missing)";
        }
    return "";
}

/// Split components must share a voxel size and orientation (their linear maps equal up to the
/// translation): a face-centred (MAC) layout, offset by half a voxel, is sampled in world space;
/// components of different resolutions or rotations are refused rather than resampled.
/// @throw lic::InputError naming each component's voxel size.
void checkSplitTransforms(const openvdb::FloatGrid::Ptr (&comp)[3], const std::string (&names)[3], const std::string& path)
{
    const auto linear = [](const openvdb::FloatGrid& g) {
        openvdb::Mat4d m = g.transform().baseMap()->getAffineMap()->getMat4();
        m.setTranslation(openvdb::Vec3d(0.0));
        return m;
    };
    const openvdb::Mat4d m0 = linear(*comp[0]);
    if (linear(*comp[1]).eq(m0, 1e-12) && linear(*comp[2]).eq(m0, 1e-12)) return;
    std::ostringstream msg;
    msg << "split velocity components in " << q(path) << " have different transforms (";
    for (int a = 0; a < 3; ++a) msg << (a ? ", " : "") << q(names[a]) << " voxel size " << comp[a]->voxelSize();
    msg << "); the three grids must share one voxel size and orientation (offsets by part of a voxel, "
           "as in a face-centred layout, are allowed)";
    throw lic::InputError(msg.str());
}

/// The value of every active voxel of `out`: component a read from comp[a] at the same index
/// coordinate (`same` transforms), else sampled trilinearly at the voxel's world position.
/// Threaded (tools::foreach, a copy of the accessors per task); each value depends only on its voxel.
void fillFromComponents(openvdb::Vec3SGrid& out, const openvdb::FloatGrid::Ptr (&comp)[3], bool same)
{
    using Sampler = openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler>;
    struct Fill
    {
        openvdb::FloatGrid::ConstAccessor acc[3];
        const openvdb::FloatGrid::Ptr (&grids)[3];
        const openvdb::math::Transform& xform;
        bool same;
        void operator()(const openvdb::Vec3SGrid::ValueOnIter& it) const
        {
            openvdb::Vec3s v;
            const openvdb::Vec3d w = same ? openvdb::Vec3d(0.0) : xform.indexToWorld(it.getCoord());
            for (int a = 0; a < 3; ++a)
                v[a] = same ? acc[a].getValue(it.getCoord()) : Sampler(acc[a], grids[a]->transform()).wsSample(w);
            it.setValue(v);
        }
    };
    // Not const: a const op would be shared by the threads, and accessors cache per thread.
    Fill fill{{comp[0]->getConstAccessor(), comp[1]->getConstAccessor(), comp[2]->getConstAccessor()},
              comp, out.transform(), same};
    openvdb::tools::foreach(out.beginValueOn(), fill, /*threaded=*/true, /*shared=*/false);
}

/// One Vec3 grid from three scalar component grids (Houdini's and EmberGen's split `vel.x`,
/// `vel.y`, `vel.z`). The result has the x grid's transform and the union of the three active
/// regions (tools: topologyUnion); components offset by part of a voxel (face-centred, MAC style)
/// are sampled trilinearly at the result's voxel centres in world space.
/// @throw lic::InputError for a component that is not a scalar grid, a non-linear transform, or
///        components of different voxel sizes or orientations (checkSplitTransforms).
openvdb::Vec3SGrid::Ptr combineSplit(detail::VdbReader& reader, const std::string& base, const std::string& sep)
{
    openvdb::FloatGrid::Ptr comp[3];
    const std::string names[3] = {base + sep + "x", base + sep + "y", base + sep + "z"};
    for (int a = 0; a < 3; ++a) {
        comp[a] = toFloat(reader.readGrid(names[a]));
        if (!comp[a]) throw lic::InputError("grid " + q(names[a]) + " in " + q(reader.path()) + " is not a scalar grid");
        if (!comp[a]->transform().isLinear())
            throw lic::InputError("grid " + q(names[a]) + " in " + q(reader.path()) + " has a non-linear transform");
    }
    checkSplitTransforms(comp, names, reader.path());
    auto out = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    out->setTransform(comp[0]->transform().copy());
    out->setName(base);
    out->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    const bool sameXform = comp[1]->transform() == comp[0]->transform() && comp[2]->transform() == comp[0]->transform();
    for (int a = 0; a < 3; ++a) {
        if (sameXform) {
            out->tree().topologyUnion(comp[a]->tree());
            continue;
        }
        const openvdb::CoordBBox bb = comp[a]->evalActiveVoxelBoundingBox();
        if (bb.empty()) continue;
        const openvdb::BBoxd w = comp[a]->transform().indexToWorld(bb);
        const openvdb::Vec3d lo = out->worldToIndex(w.min()), hi = out->worldToIndex(w.max());
        out->tree().sparseFill(openvdb::CoordBBox(openvdb::Coord::round(openvdb::math::minComponent(lo, hi)),
                                                  openvdb::Coord::round(openvdb::math::maxComponent(lo, hi))),
                               openvdb::Vec3s(0.0f), true);
    }
    out->tree().voxelizeActiveTiles();
    fillFromComponents(*out, comp, sameXform);
    return out;
}

} // namespace

openvdb::Vec3SGrid::Ptr readVelocityGrid(const std::string& path, const std::string& name,
                                         std::string* chosenName)
{
    detail::VdbReader reader(path);
    const auto grids = reader.gridTypes();
    const auto find = [&](const std::string& n) {
        return std::find_if(grids.begin(), grids.end(), [&](const auto& g) { return g.first == n; });
    };

    std::string chosen;
    if (!name.empty()) {
        const auto it = find(name);
        if (it == grids.end()) {
            std::string sep;
            if (!findSplitBase(grids, name, sep).empty()) {
                if (chosenName) *chosenName = name;
                return combineSplit(reader, name, sep);
            }
            throw lic::InputError("grid " + q(name) + " not found in " + q(path) + partialSplitNote(grids, name)
                                  + "; the file has: " + detail::listGrids(grids));
        }
        if (!detail::isVec3Type(it->second))
            throw lic::InputError("grid " + q(name) + " in " + q(path) + " is a " + it->second
                                  + " grid; a " + it->second + " grid cannot be a velocity field "
                                  "(expected a Vec3 grid: vec3s, vec3d or vec3i)");
        chosen = name;
    } else {
        for (const char* candidate : kDefaultVelocityNames) {
            const auto it = find(candidate);
            if (it != grids.end() && detail::isVec3Type(it->second)) {
                chosen = candidate;
                break;
            }
        }
        if (chosen.empty()) {
            std::vector<std::pair<std::string, std::string>> vec3;
            for (const auto& g : grids)
                if (detail::isVec3Type(g.second)) vec3.push_back(g);
            std::string sep;
            const std::string split = vec3.empty() ? findSplitBase(grids, "", sep) : "";
            if (!split.empty()) {
                if (chosenName) *chosenName = split;
                return combineSplit(reader, split, sep);
            }
            if (vec3.empty())
                throw lic::InputError(q(path) + " has no Vec3 grid to use as a velocity field" + partialSplitNote(grids, "")
                                      + "; the file has: " + detail::listGrids(grids)
                                      + "; expected a vec3s, vec3d or vec3i grid, or float grids NAME.x, NAME.y, NAME.z");
            if (vec3.size() > 1)
                throw lic::InputError(q(path) + " has several Vec3 grids and none is named "
                                      "'velocity', 'vel' or 'v': " + detail::listGrids(vec3)
                                      + "; pass --grid NAME to choose one");
            chosen = vec3.front().first;
        }
    }

    auto grid = toVec3S(reader.readGrid(chosen));
    if (!grid)
        throw lic::InputError("grid " + q(chosen) + " in " + q(path)
                              + " could not be read as a Vec3 grid");
    if (chosenName) *chosenName = chosen;
    return grid;
}

std::map<std::string, openvdb::FloatGrid::Ptr> readScalarGrids(const std::string& path)
{
    detail::VdbReader reader(path);
    std::map<std::string, openvdb::FloatGrid::Ptr> out;
    for (const auto& [name, type] : reader.gridTypes()) {
        if (type != openvdb::typeNameAsString<float>() && type != openvdb::typeNameAsString<double>())
            continue;
        if (out.count(name)) continue; // duplicate name: the first one wins, as in readGrid
        if (auto grid = toFloat(reader.readGrid(name))) out.emplace(name, std::move(grid));
    }
    return out;
}

// ------------------------------------------------------------------------------------------
// writing

// ---- OutputSet ---------------------------------------------------------------------------

namespace {

std::string fdPath(int fd) { return "/proc/self/fd/" + std::to_string(fd); }

} // namespace

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

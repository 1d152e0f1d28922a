#include "Distribute.h"

#include "vdbexport/bake/Distributed.h"

#include "lic/util/Error.h"

#ifdef LICVDB_WITH_MPI
#include <mpi.h>
#endif

#include <algorithm>
#include <climits>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <new>
#include <numeric>

#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

namespace vdbexport {

namespace {

/// MPI_Init ran in this process (MpiSession::start) and the job has not been aborted.
bool gMpiStarted = false;

const char* env(const char* name)
{
    const char* v = std::getenv(name);
    return v && *v ? v : nullptr;
}

/// The rank an MPI launcher gave this process (Open MPI's mpirun, PMIx, PMI), or −1.
int launcherRank()
{
    for (const char* name : {"OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK"})
        if (const char* v = env(name)) return std::atoi(v);
    return -1;
}

/// The number of processes an MPI launcher started (1 when unknown).
[[maybe_unused]] int launcherSize()
{
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"})
        if (const char* v = env(name)) return std::max(1, std::atoi(v));
    return 1;
}

/// Open MPI on one node: use the ob1 messaging layer (shared memory between the ranks) unless
/// the job chose one ($OMPI_MCA_pml, as `mpirun --mca pml …` sets it). Open MPI's default
/// selection also opens the `cm` layer and its network libraries (PSM, PSM2, OFI), which only
/// serve between nodes and cost ~0.2 s of MPI_Init per job here (docs/distributed.md);
/// ob1 over shared memory is what it picks on one node anyway. Read by MPI_Init from this
/// process's environment, so it must be set before. $LICVDB_MPI_PML=keep leaves the choice to
/// Open MPI (its configuration files included).
[[maybe_unused]] void preferSharedMemoryOnOneNode()
{
    const char* size = env("OMPI_COMM_WORLD_SIZE");
    const char* local = env("OMPI_COMM_WORLD_LOCAL_SIZE");
    if (!size || !local || std::string(size) != local || env("OMPI_MCA_pml")) return;
    if (const char* keep = env("LICVDB_MPI_PML"); keep && std::string(keep) == "keep") return;
    ::setenv("OMPI_MCA_pml", "ob1", /*overwrite=*/0);
}

} // namespace

// ------------------------------------------------------------------------------------------
// MpiSession

bool MpiSession::available()
{
#ifdef LICVDB_WITH_MPI
    return true;
#else
    return false;
#endif
}

void MpiSession::start(int& argc, char**& argv)
{
    const char* force = env("LICVDB_MPI");
    const bool off = force && std::string(force) == "0", on = force && std::string(force) == "1";
    const bool launched = launcherRank() >= 0;
    if (off || (!on && !launched)) return;
#ifdef LICVDB_WITH_MPI
    preferSharedMemoryOnOneNode();
    int provided = 0;
    if (MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
        throw lic::Error("MPI failed to start (MPI_Init_thread); run without mpirun, or set LICVDB_MPI=0");
    mStarted = gMpiStarted = true;
    MPI_Comm_rank(MPI_COMM_WORLD, &mRank);
    MPI_Comm_size(MPI_COMM_WORLD, &mSize);
#else
    (void)argc;
    (void)argv;
    if (on || launcherSize() > 1) {
        throw lic::InputError("this licvdb was built without MPI, so " + std::to_string(launcherSize()) +
                              " processes would each bake the whole volume into the same file; rebuild with "
                              "-DLICVDB_MPI=ON (apt-get install libopenmpi-dev), or run it without mpirun");
    }
#endif
}

MpiSession::~MpiSession()
{
#ifdef LICVDB_WITH_MPI
    if (mStarted && gMpiStarted) {
        MPI_Finalize();
        gMpiStarted = false;
    }
#endif
}

bool MpiSession::reportsErrors() const
{
    if (!mStarted) return launcherRank() <= 0; // before MPI: every rank fails alike; one reports
    return mRank == 0 || !pipeline::Job::current().failed();
}

std::string MpiSession::errorPrefix() const
{
    if (!mStarted || mSize <= 1 || pipeline::Job::current().failed()) return "";
    return "rank " + std::to_string(mRank) + " of " + std::to_string(mSize) + ": ";
}

int MpiSession::failed(int code)
{
#ifdef LICVDB_WITH_MPI
    if (mStarted && mSize > 1 && !pipeline::Job::current().failed()) {
        std::cerr.flush();
        gMpiStarted = false;
        MPI_Abort(MPI_COMM_WORLD, code);
    }
#endif
    return code;
}

namespace pipeline {

// ------------------------------------------------------------------------------------------
// Job

Job& Job::current()
{
    static Job job;
    return job;
}

Job::Job()
{
#ifdef LICVDB_WITH_MPI
    int initialised = 0, finalised = 0;
    MPI_Initialized(&initialised);
    MPI_Finalized(&finalised);
    if (initialised && !finalised) {
        MPI_Comm_rank(MPI_COMM_WORLD, &mRank);
        MPI_Comm_size(MPI_COMM_WORLD, &mSize);
    }
#endif
}

namespace {

enum FailureKind : int { kNone = 0, kInput = 1, kRuntime = 2, kCancelled = 3 };

/// The kind and message of a failure, for the other ranks.
FailureKind classify(std::exception_ptr e, std::string& message)
{
    try {
        std::rethrow_exception(e);
    } catch (const lic::Cancelled&) {
        message = "cancelled";
        return kCancelled;
    } catch (const lic::InputError& x) {
        message = x.what();
        return kInput;
    } catch (const std::bad_alloc&) {
        message = "out of memory; give each rank more memory (fewer ranks per node), or share the bake among "
                  "more ranks";
        return kRuntime;
    } catch (const std::exception& x) {
        message = x.what();
        return kRuntime;
    } catch (...) {
        message = "unknown error";
        return kRuntime;
    }
}

#ifdef LICVDB_WITH_MPI
constexpr int kTagSize = 701, kTagData = 702;
constexpr std::size_t kChunk = std::size_t(1) << 30; // bytes per message: MPI counts are int

void sendBytes(const std::string& bytes, int to)
{
    const std::uint64_t n = bytes.size();
    MPI_Send(&n, 1, MPI_UINT64_T, to, kTagSize, MPI_COMM_WORLD);
    for (std::size_t at = 0; at < n; at += kChunk)
        MPI_Send(bytes.data() + at, int(std::min(kChunk, n - at)), MPI_BYTE, to, kTagData, MPI_COMM_WORLD);
}

std::string receiveBytes(int from)
{
    std::uint64_t n = 0;
    MPI_Recv(&n, 1, MPI_UINT64_T, from, kTagSize, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    std::string bytes(n, '\0');
    for (std::size_t at = 0; at < n; at += kChunk)
        MPI_Recv(bytes.data() + at, int(std::min<std::size_t>(kChunk, n - at)), MPI_BYTE, from, kTagData, MPI_COMM_WORLD,
                 MPI_STATUS_IGNORE);
    return bytes;
}
#endif

// Leaves on the wire: leaf count, then per leaf its origin, value mask and active values in
// offset order (inactive voxels of our leaves always hold zero).
template<typename T>
void put(std::string& out, const T& v)
{
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
}

template<typename T>
T take(const std::string& in, std::size_t& at)
{
    if (at + sizeof(T) > in.size()) throw lic::Error("truncated leaf message");
    T v;
    std::memcpy(&v, in.data() + at, sizeof v);
    at += sizeof v;
    return v;
}

template<typename GridT>
std::string packLeaves(const GridT& grid)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    constexpr std::size_t kMaskBytes = LeafT::NodeMaskType::WORD_COUNT * sizeof(std::uint64_t);
    std::string out;
    std::size_t bytes = sizeof(std::uint64_t);
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf)
        bytes += 3 * sizeof(std::int32_t) + kMaskBytes + leaf->onVoxelCount() * sizeof(ValueT);
    out.reserve(bytes);
    put(out, std::uint64_t(grid.tree().leafCount()));
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        const openvdb::Coord o = leaf->origin();
        for (int a = 0; a < 3; ++a) put(out, std::int32_t(o[a]));
        for (openvdb::Index w = 0; w < LeafT::NodeMaskType::WORD_COUNT; ++w)
            put(out, leaf->getValueMask().template getWord<std::uint64_t>(w));
        if (leaf->getValueMask().isOn() && leaf->buffer().data()) {
            // Every voxel active (a dense bake's leaves): the values in offset order are the buffer.
            out.append(reinterpret_cast<const char*>(leaf->buffer().data()), LeafT::SIZE * sizeof(ValueT));
        } else {
            for (auto it = leaf->cbeginValueOn(); it; ++it) put(out, *it);
        }
    }
    return out;
}

template<typename GridT>
void unpackLeaves(GridT& grid, const std::string& in)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    std::size_t at = 0;
    const auto count = take<std::uint64_t>(in, at);
    for (std::uint64_t i = 0; i < count; ++i) {
        openvdb::Coord o;
        for (int a = 0; a < 3; ++a) o[a] = take<std::int32_t>(in, at);
        typename LeafT::NodeMaskType mask;
        for (openvdb::Index w = 0; w < LeafT::NodeMaskType::WORD_COUNT; ++w)
            mask.template getWord<std::uint64_t>(w) = take<std::uint64_t>(in, at);
        if (grid.tree().probeConstLeaf(o)) {
            throw lic::Error("the leaf at (" + std::to_string(o[0]) + ", " + std::to_string(o[1]) + ", " +
                             std::to_string(o[2]) + ") of grid " + grid.getName() + " came from two ranks");
        }
        auto leaf = std::make_unique<LeafT>(o, openvdb::zeroVal<ValueT>(), false);
        if (mask.isOn()) {
            // Every voxel active: the values are the buffer, in offset order.
            constexpr std::size_t n = LeafT::SIZE * sizeof(ValueT);
            if (at + n > in.size()) throw lic::Error("truncated leaf message");
            std::memcpy(static_cast<void*>(leaf->buffer().data()), in.data() + at, n);
            at += n;
            leaf->setValueMask(mask);
        } else {
            for (auto it = mask.beginOn(); it; ++it) leaf->setValueOn(it.pos(), take<ValueT>(in, at));
        }
        grid.tree().addLeaf(leaf.release());
    }
    if (at != in.size()) throw lic::Error("leaf message of grid " + grid.getName() + " has trailing bytes");
}

} // namespace

void Job::agree(std::exception_ptr local, const char* what)
{
    if (!distributed()) {
        if (local) std::rethrow_exception(local);
        return;
    }
#ifdef LICVDB_WITH_MPI
    std::string message;
    const FailureKind kind = local ? classify(local, message) : kNone;
    int mine = local ? mRank : mSize, first = mSize;
    MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (first == mSize) return;
    int failing = local ? 1 : 0, count = 0;
    MPI_Allreduce(&failing, &count, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
    int header[2] = {int(kind), int(std::min<std::size_t>(message.size(), 1 << 20))};
    MPI_Bcast(header, 2, MPI_INT, first, MPI_COMM_WORLD);
    message.resize(std::size_t(header[1]));
    MPI_Bcast(message.data(), header[1], MPI_CHAR, first, MPI_COMM_WORLD);
    mFailed = true;
    if (header[0] == kCancelled) throw lic::Cancelled();
    std::string text = count == mSize ? "all " + std::to_string(mSize) + " ranks"
                                      : "rank " + std::to_string(first) + " of " + std::to_string(mSize);
    if (count > 1 && count < mSize)
        text += " (and " + std::to_string(count - 1) + " other rank" + (count > 2 ? "s" : "") + ")";
    text += " failed while " + std::string(what) + ": " + message;
    if (header[0] == kInput) throw lic::InputError(text);
    throw lic::Error(text);
#else
    (void)what;
#endif
}

double Job::maxAll(double v, const char* what)
{
    if (!distributed()) return v;
    agree(nullptr, what);
    double out = v;
#ifdef LICVDB_WITH_MPI
    MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
#endif
    return out;
}

void Job::sumAll(std::vector<std::uint64_t>& v, const char* what)
{
    if (!distributed()) return;
    agree(nullptr, what);
#ifdef LICVDB_WITH_MPI
    constexpr std::size_t kMax = std::size_t(INT_MAX) / 2;
    for (std::size_t at = 0; at < v.size(); at += kMax)
        MPI_Allreduce(MPI_IN_PLACE, v.data() + at, int(std::min(kMax, v.size() - at)), MPI_UINT64_T, MPI_SUM,
                      MPI_COMM_WORLD);
#endif
}

std::uint64_t Job::sumAll(std::uint64_t v, const char* what)
{
    std::vector<std::uint64_t> one{v};
    sumAll(one, what);
    return one[0];
}

std::vector<std::string> Job::allGather(const std::string& bytes, const char* what)
{
    if (!distributed()) return {bytes};
    agree(nullptr, what);
    std::vector<std::string> out(static_cast<std::size_t>(mSize));
#ifdef LICVDB_WITH_MPI
    std::vector<std::uint64_t> sizes(std::size_t(mSize), 0);
    const std::uint64_t mine = bytes.size();
    MPI_Allgather(&mine, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD);
    for (int r = 0; r < mSize; ++r) {
        std::string& s = out[std::size_t(r)];
        if (r == mRank) s = bytes;
        else s.resize(sizes[std::size_t(r)]);
        for (std::size_t at = 0; at < s.size(); at += kChunk)
            MPI_Bcast(s.data() + at, int(std::min(kChunk, s.size() - at)), MPI_BYTE, r, MPI_COMM_WORLD);
    }
#endif
    return out;
}

std::vector<std::string> Job::exchange(std::vector<std::string> out, const char* what)
{
    if (out.size() != std::size_t(mSize)) throw lic::Error("internal error: exchange needs one message per rank");
    if (!distributed()) return out;
    agree(nullptr, what);
    std::vector<std::string> in(static_cast<std::size_t>(mSize));
#ifdef LICVDB_WITH_MPI
    try {
        std::vector<std::uint64_t> sendSizes(static_cast<std::size_t>(mSize)), recvSizes(static_cast<std::size_t>(mSize));
        for (int r = 0; r < mSize; ++r) sendSizes[std::size_t(r)] = out[std::size_t(r)].size();
        MPI_Alltoall(sendSizes.data(), 1, MPI_UINT64_T, recvSizes.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD);
        std::vector<MPI_Request> requests;
        for (int r = 0; r < mSize; ++r) {
            if (r == mRank) continue;
            std::string& s = in[std::size_t(r)];
            s.resize(recvSizes[std::size_t(r)]);
            for (std::size_t at = 0; at < s.size(); at += kChunk) {
                requests.emplace_back();
                MPI_Irecv(s.data() + at, int(std::min(kChunk, s.size() - at)), MPI_BYTE, r, kTagData, MPI_COMM_WORLD,
                          &requests.back());
            }
        }
        for (int r = 0; r < mSize; ++r) {
            if (r == mRank) continue;
            const std::string& s = out[std::size_t(r)];
            for (std::size_t at = 0; at < s.size(); at += kChunk) {
                requests.emplace_back();
                MPI_Isend(s.data() + at, int(std::min(kChunk, s.size() - at)), MPI_BYTE, r, kTagData, MPI_COMM_WORLD,
                          &requests.back());
            }
        }
        MPI_Waitall(int(requests.size()), requests.data(), MPI_STATUSES_IGNORE);
    } catch (const std::bad_alloc&) {
        abort("licvdb bake: error: rank " + std::to_string(mRank) + " of " + std::to_string(mSize) +
                  " ran out of memory while " + what,
              1);
    }
#endif
    in[std::size_t(mRank)] = std::move(out[std::size_t(mRank)]);
    return in;
}

void Job::gatherLeaves(openvdb::GridPtrVec& grids, const std::vector<bool>& skip)
{
    if (!distributed()) return;
#ifdef LICVDB_WITH_MPI
    try {
        auto each = [&](auto&& fn) {
            for (std::size_t i = 0; i < grids.size(); ++i) {
                if (i < skip.size() && skip[i]) continue;
                openvdb::GridBase& g = *grids[i];
                if (auto* f = dynamic_cast<openvdb::FloatGrid*>(&g)) fn(*f);
                else if (auto* v = dynamic_cast<openvdb::Vec3SGrid*>(&g)) fn(*v);
                else throw lic::Error("grid " + g.getName() + " of type " + g.valueType() + " cannot be gathered");
            }
        };
        if (root()) {
            for (int r = 1; r < mSize; ++r) each([&](auto& grid) { unpackLeaves(grid, receiveBytes(r)); });
        } else {
            each([&](const auto& grid) { sendBytes(packLeaves(grid), 0); });
        }
    } catch (const std::bad_alloc&) {
        abort("licvdb bake: error: rank " + std::to_string(mRank) + " of " + std::to_string(mSize) +
                  " ran out of memory while gathering a frame's leaves on rank 0; rank 0 holds one frame's grids",
              1);
    } catch (const std::exception& e) {
        abort("licvdb bake: error: rank " + std::to_string(mRank) + " of " + std::to_string(mSize) +
                  " failed while gathering a frame's leaves: " + e.what(),
              1);
    }
#else
    (void)grids;
    (void)skip;
#endif
}

void Job::abort(const std::string& message, int code)
{
    std::cerr << message << std::endl;
#ifdef LICVDB_WITH_MPI
    if (gMpiStarted) {
        gMpiStarted = false;
        MPI_Abort(MPI_COMM_WORLD, code);
    }
#endif
    std::_Exit(code);
}

void Job::injectFault(const char* what) const
{
    static const char* spec = std::getenv("LICVDB_TEST_FAULT");
    if (!spec || !*spec) return;
    const std::string s(spec);
    const std::size_t a = s.find(':'), b = s.find(':', a == std::string::npos ? a : a + 1);
    if (a == std::string::npos || b == std::string::npos) return;
    if (std::atoi(s.substr(0, a).c_str()) != mRank) return;
    const std::string stage = s.substr(a + 1, b - a - 1), kind = s.substr(b + 1);
    const std::string phrase(what);
    if (phrase.compare(0, stage.size(), stage) != 0 || stage.empty()) return;
    const std::string msg = "injected test fault (LICVDB_TEST_FAULT=" + s + ")";
    if (kind == "input") throw lic::InputError(msg);
    if (kind == "error") throw lic::Error(msg);
    if (kind == "oom") throw std::bad_alloc();
    if (kind == "kill") std::raise(SIGKILL);
}

// ------------------------------------------------------------------------------------------
// WriteGuard

namespace {

std::vector<std::string> gGuardTemps; // prepared before the handler is installed
volatile std::sig_atomic_t gGuardArmed = 0;
struct sigaction gGuardPrevious;

extern "C" void onTerminate(int sig)
{
    if (gGuardArmed)
        for (const std::string& t : gGuardTemps) ::unlink(t.c_str());
    ::signal(sig, SIG_DFL);
    ::raise(sig);
}

} // namespace

WriteGuard::WriteGuard(const std::vector<std::string>& frames, const std::string& manifest)
{
    gGuardTemps.clear();
    const std::string suffix = ".tmp-" + std::to_string(::getpid());
    for (const std::string& f : frames) gGuardTemps.push_back(f + suffix);
    gGuardTemps.push_back(manifest + suffix);
    gGuardArmed = 1;
    struct sigaction sa {};
    sa.sa_handler = onTerminate;
    sigemptyset(&sa.sa_mask);
    ::sigaction(SIGTERM, &sa, &gGuardPrevious);
}

WriteGuard::~WriteGuard()
{
    gGuardArmed = 0;
    ::sigaction(SIGTERM, &gGuardPrevious, nullptr);
}

void WriteGuard::disarm() { gGuardArmed = 0; }

// ------------------------------------------------------------------------------------------
// Assignment

namespace {

/// Interleaved bits of three 21-bit coordinates (x highest): the Morton (Z-order) key.
std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z)
{
    auto spread = [](std::uint64_t v) {
        v &= 0x1fffff;
        v = (v | v << 32) & 0x1f00000000ffffULL;
        v = (v | v << 16) & 0x1f0000ff0000ffULL;
        v = (v | v << 8) & 0x100f00f00f00f00fULL;
        v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
        v = (v | v << 2) & 0x1249249249249249ULL;
        return v;
    };
    return spread(x) << 2 | spread(y) << 1 | spread(z);
}

} // namespace

std::vector<std::size_t> mortonOrder(const lic::BrickLayout& layout)
{
    const std::size_t n = layout.size();
    openvdb::Coord lo = openvdb::Coord::max();
    for (const lic::Brick& b : layout.bricks()) lo = openvdb::Coord::minComponent(lo, b.box.min());
    std::vector<std::pair<std::uint64_t, std::size_t>> keyed(n);
    const int d = layout.dim();
    for (std::size_t i = 0; i < n; ++i) {
        const openvdb::Coord c = layout[i].box.min() - lo;
        keyed[i] = {morton(std::uint32_t(c[0] / d), std::uint32_t(c[1] / d), std::uint32_t(c[2] / d)), layout[i].id};
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<std::size_t> ids(n);
    for (std::size_t i = 0; i < n; ++i) ids[i] = keyed[i].second;
    return ids;
}

std::vector<int> assignBricks(const lic::BrickLayout& layout, int ranks)
{
    const std::size_t n = layout.size();
    std::vector<int> out(n, 0);
    if (n == 0 || ranks <= 1) return out;
    const std::vector<std::size_t> order = mortonOrder(layout);
    // Exact in 64 bits: at most 2^31 active output voxels (OutputDomain) times 2 times the ranks.
    std::uint64_t total = 0;
    for (const lic::Brick& b : layout.bricks()) total += b.activeVoxels;
    std::uint64_t before = 0;
    for (std::size_t id : order) {
        const std::uint64_t w = layout[id].activeVoxels;
        // The rank whose share [r·T/N, (r+1)·T/N) holds the brick's middle voxel.
        const std::uint64_t middle2 = 2 * before + w; // twice the middle, in voxels
        out[id] = int(std::min<std::uint64_t>(middle2 * std::uint64_t(ranks) / (2 * total), std::uint64_t(ranks - 1)));
        before += w;
    }
    return out;
}

double peakRssMiB()
{
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0; // Linux: ru_maxrss is in KiB
}

double cpuSeconds()
{
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    auto s = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
    return s(u.ru_utime) + s(u.ru_stime);
}

std::vector<std::size_t> bricksOf(const std::vector<int>& assignment, int rank)
{
    std::vector<std::size_t> ids;
    for (std::size_t i = 0; i < assignment.size(); ++i)
        if (assignment[i] == rank) ids.push_back(i);
    return ids;
}

} // namespace pipeline
} // namespace vdbexport

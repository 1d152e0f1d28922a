// Distribution of a bake over the processes of an MPI job (`mpirun -np N licvdb bake …`).
//
// Bricks are the unit of work: each rank convolves and composites a contiguous run of bricks
// (in Morton order, balanced by active voxels) from the part of the field they need; then each
// frame's leaves go to rank 0, which writes the one file (or sequence) and the manifest. A
// brick's result depends only on the brick, and everything merged across ranks is either
// integer (histograms, counts), exact (maxima) or merged in brick-id order (contrast moments),
// so the output is bit-identical to one process for any N.
//
// Errors: every collective operation starts by agreeing on errors, and a stage that throws on a
// rank reports it at its next agreement point, so every rank leaves with the same message and
// exit code (stage()); what cannot be agreed on (an error in the middle of a transfer) ends the
// job with MPI_Abort. Without MPI (or in a plain `licvdb bake`) the Job has one process and
// every operation here is a no-op.
#pragma once

#include "lic/field/Bricks.h"
#include "lic/util/Error.h"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <exception>
#include <string>
#include <type_traits>
#include <vector>

namespace vdbexport::pipeline {

/// The processes that share one bake: the ranks of MPI_COMM_WORLD when MPI is initialised
/// (see vdbexport::MpiSession), else this process alone.
class Job
{
public:
    /// The job of this process.
    static Job& current();

    int rank() const { return mRank; }
    int size() const { return mSize; }
    bool distributed() const { return mSize > 1; }
    bool root() const { return mRank == 0; }
    /// True once the ranks agreed on a failure (every rank is leaving the bake together).
    bool failed() const { return mFailed; }

    /// Run one stage of the bake (`what`: "reading the field", "convolving", …): `fn()` here,
    /// then agree with every rank on whether any failed. In one process, just `fn()`.
    /// @throw the agreed failure on every rank: lic::InputError (bad input, exit 2),
    ///        lic::Cancelled, or lic::Error (runtime failure, out of memory; exit 1), its message
    ///        naming the first failing rank.
    template<typename Fn>
    auto stage(const char* what, Fn&& fn) -> decltype(fn());

    /// Agreement point: `local` is this rank's failure (or null). Returns when no rank failed.
    /// @throw the agreed failure (see stage()).
    void agree(std::exception_ptr local, const char* what);

    // Collective operations: every rank must call them in the same order; each first agrees on
    // errors (a failing rank's next agreement point matches it).
    /// Largest `v` over the ranks (exact, any order).
    double maxAll(double v, const char* what);
    /// Element-wise sums over the ranks, in place (integers: exact in any order).
    void sumAll(std::vector<std::uint64_t>& v, const char* what);
    std::uint64_t sumAll(std::uint64_t v, const char* what);
    /// Every rank's `bytes`, by rank, on every rank.
    std::vector<std::string> allGather(const std::string& bytes, const char* what);

    /// Point-to-point exchange: `out[r]` goes to rank r (out.size() == size()); returns what
    /// each rank sent this one, by rank (its own out[rank()] included). Follows an agreement
    /// point; an error in the middle of the transfer aborts the job.
    std::vector<std::string> exchange(std::vector<std::string> out, const char* what);

    /// The leaves of a frame's grids: the root adds every other rank's leaves to `grids` (rank by
    /// rank, grid by grid); the others send theirs. Grids whose index is in `skip` (the static
    /// grids already gathered with an earlier frame) are left out. Follows an agreement point.
    /// An error in the middle of the transfer aborts the job.
    void gatherLeaves(openvdb::GridPtrVec& grids, const std::vector<bool>& skip);

    /// End the whole job now (MPI_Abort) after printing `message` on this rank's stderr.
    [[noreturn]] void abort(const std::string& message, int code);

    /// Test hook: when $LICVDB_TEST_FAULT is "RANK:STAGE:KIND" and this rank and stage match,
    /// fail as KIND says: input (lic::InputError), error (lic::Error), oom (std::bad_alloc),
    /// kill (SIGKILL to itself). STAGE is a stage() name's first word (read, scalars, input,
    /// convolve, compose, write).
    void injectFault(const char* what) const;

private:
    Job();
    int mRank = 0;
    int mSize = 1;
    bool mFailed = false;
};

/// While armed, SIGTERM (what mpirun sends every rank when one of them dies or the job is
/// cancelled) makes rank 0 remove the named temporaries of the files it is staging
/// (PATH.tmp-PID, where the file system has no O_TMPFILE; see vdbexport::OutputSet), then die
/// of the signal. Staged files are unnamed until the manifest commits them all together, so a
/// job killed before that leaves no file, old outputs untouched. Only async-signal-safe calls
/// run in the handler (unlink on names prepared in advance).
class WriteGuard
{
public:
    /// `frames`: every frame path of the bake, in order; `manifest`: its manifest path.
    WriteGuard(const std::vector<std::string>& frames, const std::string& manifest);
    ~WriteGuard(); ///< restores the previous SIGTERM handler
    WriteGuard(const WriteGuard&) = delete;
    WriteGuard& operator=(const WriteGuard&) = delete;
    /// The bake is complete: a signal now removes nothing.
    void disarm();
};

/// Peak resident memory of this process so far, MiB (a rank's figure in a bake's summary).
double peakRssMiB();
/// CPU time of this process so far (user + system, every thread), seconds: with the wall times,
/// how much of a core a process had (a shared machine gives less than its threads ask for).
double cpuSeconds();

/// The ids of `layout`'s bricks in Morton (Z-curve) order of their positions: neighbours in the
/// order are neighbours in space, so a run of the order is a compact region.
std::vector<std::size_t> mortonOrder(const lic::BrickLayout& layout);

/// Which rank convolves each brick of `layout` (indexed by brick id): bricks in Morton order of
/// their position (mortonOrder()), cut into `ranks` contiguous runs of about equal active voxels
/// (a brick goes to the rank whose share [r·T/N, (r+1)·T/N) of the T voxels holds its middle
/// voxel; with more ranks than bricks some ranks get none). Deterministic: a function of the layout
/// only, never of timing; contiguous runs keep each rank's part of the field compact.
std::vector<int> assignBricks(const lic::BrickLayout& layout, int ranks);

/// The ids of the bricks assigned to `rank`, ascending.
std::vector<std::size_t> bricksOf(const std::vector<int>& assignment, int rank);

// ------------------------------------------------------------------------------------------

template<typename Fn>
auto Job::stage(const char* what, Fn&& fn) -> decltype(fn())
{
    using R = decltype(fn());
    if (!distributed()) {
        injectFault(what);
        return fn();
    }
    std::exception_ptr local;
    try {
        injectFault(what);
        if constexpr (std::is_void_v<R>) {
            fn();
            agree(nullptr, what);
            return;
        } else {
            R result = fn();
            agree(nullptr, what);
            return result;
        }
    } catch (...) {
        if (mFailed) throw; // agreed already (in agree() above or in a collective inside fn)
        local = std::current_exception();
    }
    agree(local, what); // throws
    throw lic::Error("internal error: a failure was not agreed on");
}

} // namespace vdbexport::pipeline

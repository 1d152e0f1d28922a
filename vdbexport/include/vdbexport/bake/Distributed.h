// MPI for `licvdb bake` under mpirun or srun (a distributed bake: see docs/distributed.md).
// The same binary runs without a launcher exactly as a single process: MPI is initialised only
// when the process was started by an MPI launcher, and only when licvdb was built with MPI
// (CMake option LICVDB_MPI).
#pragma once

#include <string>

namespace vdbexport {

/// MPI's lifetime in `main`. Declare one before the command runs; start() it for a bake.
class MpiSession
{
public:
    MpiSession() = default;
    /// MPI_Finalize if start() initialised MPI and the job was not aborted.
    ~MpiSession();
    MpiSession(const MpiSession&) = delete;
    MpiSession& operator=(const MpiSession&) = delete;

    /// Initialise MPI (MPI_THREAD_FUNNELED: only the main thread calls MPI) when this build has
    /// MPI and the environment shows an MPI launcher (Open MPI's mpirun, a PMI/PMIx launcher
    /// such as srun); $LICVDB_MPI=0 turns it off, $LICVDB_MPI=1 forces it.
    /// @throw lic::Error if $LICVDB_MPI=1 in a build without MPI, or if MPI fails to start.
    void start(int& argc, char**& argv);

    /// This process's rank (0 without MPI) and the number of ranks (1 without MPI).
    int rank() const { return mRank; }
    int size() const { return mSize; }
    bool distributed() const { return mSize > 1; }

    /// Whether this process should print an error that ended the command: the root always; the
    /// other ranks only when the failure was theirs alone (not agreed by every rank).
    bool reportsErrors() const;
    /// "rank R of N: " for an error this rank met alone in a distributed bake (agreed errors
    /// already name the failing rank), else "".
    std::string errorPrefix() const;
    /// The exit code for a command that failed with `code`: returns it when every rank agreed
    /// on the failure (they all leave together), else aborts the whole job with it (the other
    /// ranks may be waiting for this one).
    int failed(int code);

    /// True when licvdb was built with MPI.
    static bool available();

private:
    bool mStarted = false;
    int mRank = 0;
    int mSize = 1;
};

} // namespace vdbexport

// Checking an untrusted .vdb file against itself before OpenVDB reads it (layer 1 of the read
// defences; see docs/inputs.md), and reading it once in a disposable child process (layer 2).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <sys/types.h>

namespace vdbexport {

/// @brief How every refusal by checkVdbStructure (layer 1) begins: the marker, the name of the
///        rule that refused the file, "] ", then the message, e.g.
///        `[vdb-check blosc-nbytes] 'f.vdb' is corrupt: grid 'vel', leaf at (0, 8, 0): a blosc
///        block claims 8182 bytes where 6144 are expected (at byte 1234); expected an intact
///        OpenVDB .vdb file`. OpenVDB's own read errors (`cannot read 'f.vdb' (…): …`,
///        `cannot open 'f.vdb' as a .vdb file: …`) and the isolated read's (`reading 'f.vdb'
///        crashed OpenVDB's reader …`, `… did not finish within …`) never begin with it. The rule
///        names are listed in docs/inputs.md.
inline constexpr std::string_view kVdbCheckMarker = "[vdb-check ";

/// The name of the rule in a layer-1 refusal message (where the marker first appears in
/// `message`, e.g. after `licvdb bake: error: `), or "" if `message` has no marker.
std::string vdbCheckRule(const std::string& message);

/// What the structural check found in one grid of a .vdb file.
struct VdbGridCheck
{
    std::string name;       ///< grid name as OpenVDB reports it (`vel`, or `vel[1]` for duplicates)
    std::string gridType;   ///< tree type without the half-float suffix, e.g. `Tree_vec3s_5_4_3`
    std::string valueType;  ///< `float`, `vec3s`, …; empty if licvdb does not read this type
    std::string skipReason; ///< why the tree was not walked (unsupported type); empty if it was
    bool halfFloat = false; ///< values stored as 16-bit floats
    bool instance = false;  ///< shares the tree of `instanceParent`
    std::string instanceParent;
    uint32_t compression = 0; ///< io::COMPRESS_* flags of the grid
    uint64_t tiles = 0, internalNodes = 0, leaves = 0;
    uint64_t leafVoxelsOn = 0; ///< active voxels in leaves (active tiles not counted)
};

/// What the structural check found in a .vdb file.
struct VdbCheckResult
{
    uint32_t fileVersion = 0;
    uint32_t libraryMajor = 0, libraryMinor = 0;
    uint64_t fileBytes = 0;
    /// Estimated memory OpenVDB needs to hold every checked grid, in bytes (nodes and buffers).
    uint64_t memoryBytes = 0;
    std::vector<VdbGridCheck> grids;
};

/// How deep checkVdbStructure looks (see there).
enum class VdbCheckDepth { Full, Layout };

/// @brief Walk a .vdb file's whole structure with bounds-checked reads, as OpenVDB 10 would read
///        it, and refuse it before OpenVDB copies anything if any count, size or offset stored in
///        the file disagrees with the file itself.
///
/// Checked: the header (magic, format version 222–224), the file and grid metadata (string and
/// value sizes, the `__delayedload` table and its blosc blocks), the table of grids (names unique,
/// instance parents present and of the same type, every grid's byte range inside the file and
/// consistent with what it holds), each transform (known map type, finite, non-degenerate), and
/// each tree: buffer count, root tiles and children (aligned, unique, within ±2^30), internal
/// node masks (no slot both child and value), and for every node's value block and every leaf
/// buffer the byte count it stores against what that node can hold given the grid's compression
/// flags and half-float storage (the `is_saved_as_half_float` metadata, which OpenVDB 10 obeys;
/// per-node mask metadata, inactive values, selection mask, raw,
/// zip or blosc block: its header sizes must match, and it is decoded into a guarded scratch
/// buffer that must come out exactly full). Grid types licvdb does not read (point grids) have
/// their metadata and transform checked and their tree skipped (VdbGridCheck::skipReason).
/// Memory: refuses a file whose grids would need more than readMemoryLimitBytes().
/// @param path  the .vdb file
/// @return what was found (grids in file order)
/// @throw lic::InputError beginning with kVdbCheckMarker and the rule's name, naming `path`,
///        where in the file (grid, node origin, byte offset) and what is wrong: not a VDB file,
///        truncated, unsupported format version, corrupt, or too large.
/// @param depth  Full (the default, for every file read) or Layout: every rule but the decoding of
///        compressed blocks (their headers and sizes are still checked) and the memory limit: for
///        a file licvdb has just written, where what is checked is that it was written whole (a
///        full disk cuts it short), not that an untrusted writer made it.
VdbCheckResult checkVdbStructure(const std::string& path, VdbCheckDepth depth = VdbCheckDepth::Full);

/// @brief The memory a file's grids may need for checkVdbStructure to pass it, in bytes: 80 % of
///        this machine's physical memory, or $LICVDB_READ_MEMORY_MB MiB if set (> 0); 0 (no
///        limit) if neither is known.
uint64_t readMemoryLimitBytes();

/// @brief Layer 2: read every grid of `path` with OpenVDB in a separate process (`licvdb-readcheck`
///        or `licvdb info --check`, see setReadIsolation), so that a file that crashes or hangs OpenVDB takes down
///        only that process. Does nothing while no executable is set (library use, the child).
/// Waits at most readTimeoutSeconds(file size), then kills the child.
/// @throw lic::InputError if the child reports the file corrupt (its reason), is killed by a
///        signal (the file crashed the reader) or runs out of time; lic::Error if the child cannot
///        be started or fails for another reason.
void checkInIsolatedProcess(const std::string& path);

/// @brief A child check started but not yet waited for, so that the caller can do other work
///        meanwhile (checkedVdb runs layer 1 beside it). finish() waits for its verdict and throws
///        as checkInIsolatedProcess; a check dropped unfinished is stopped (the child killed and
///        reaped). An empty check (isolation off) finishes at once.
class IsolatedCheck
{
public:
    IsolatedCheck() = default;
    IsolatedCheck(IsolatedCheck&& other) noexcept;
    IsolatedCheck& operator=(IsolatedCheck&&) = delete;
    IsolatedCheck(const IsolatedCheck&) = delete;
    IsolatedCheck& operator=(const IsolatedCheck&) = delete;
    ~IsolatedCheck();

    /// Start `exe args...` as the child reading `path` (LICVDB_READ_CHILD=1, stderr collected).
    /// @throw lic::Error if it cannot be started.
    static IsolatedCheck start(const std::string& exe, const std::string& path, const std::vector<std::string>& args,
                               const std::string& reader, const std::string& expected);
    /// Take over a child already running (this process's own, reading `path`; its stderr's read
    /// end `errFd`): the fork server's.
    static IsolatedCheck adopt(pid_t pid, int errFd, const std::string& path, const std::string& reader,
                               const std::string& expected);
    void finish();

private:
    void stop() noexcept;

    pid_t mPid = -1;
    int mErrFd = -1;
    std::string mPath, mReader, mExpected;
    double mLimit = 0;
    std::chrono::steady_clock::time_point mT0{};
};

/// The check checkInIsolatedProcess(path) runs, started (an empty one while isolation is off).
IsolatedCheck startIsolatedCheck(const std::string& path);

/// @brief The same for any reader: run the set executable with `args` (e.g. `convert PATH --list`
///        for a mesh, read by VTK) in a child process with LICVDB_READ_CHILD=1. `reader` names the
///        reader in the crash message ("VTK's reader"), `expected` what an intact file is.
/// @throw as checkInIsolatedProcess.
void checkReadInIsolatedProcess(const std::string& path, const std::vector<std::string>& args, const std::string& reader,
                                const std::string& expected);

/// @brief Set the executable that checkInIsolatedProcess runs (`licvdb`); empty turns layer 2 off.
/// `licvdb` sets itself at start-up, except in the child (environment LICVDB_READ_CHILD=1).
/// `vdbHelper`: a program that checks a .vdb as `licvdb info --check` does in the child, run as
/// `HELPER -- FILE` (`licvdb-readcheck`, which starts in a fraction of licvdb's time); "" = use
/// `executable` for .vdb files too.
void setReadIsolation(const std::string& executable, const std::string& vdbHelper = "");

/// `licvdb-readcheck` installed beside `executable` (the build tree, or the same bin directory)
/// or in its ../libexec/licvdb/ (an installed licvdb); "" if there is none.
std::string findVdbReadHelper(const std::string& executable);

/// The executable set by setReadIsolation ("" if none).
std::string readIsolationExecutable();

/// @brief Start layer 2's fork server: a process forked from this one now, which stays
///        single-threaded and forks one child per .vdb check that runs `check(path)` (its return
///        value is the child's exit code, as licvdb-readcheck's: detail::readCheckMain). Such a
///        child starts in a few milliseconds, where a program takes 50–80 ms to link OpenVDB. Each
///        child is handed to this process (which becomes its subreaper), so startIsolatedCheck
///        waits for it, times it out and kills it exactly as a started program.
///        Call it before this process starts threads of its own (TBB's among them): the server's
///        children must not inherit a half-copied thread pool. Only .vdb checks use it (a mesh
///        is still checked by a program, checkReadInIsolatedProcess); a check falls back to a
///        program if the server has gone.
/// @return false if it could not be started (checks then start programs as before).
bool startReadCheckServer(std::function<int(const std::string& path)> check);

/// Stop the fork server (tests); checks start programs again.
void stopReadCheckServer();

/// The fork server's process id, -1 when none is running (tests).
pid_t readCheckServerPid();

/// @brief Time allowed for the isolated read of a file of `fileBytes` bytes, in seconds: 20 s plus
///        1 s per 10 MB, or $LICVDB_READ_TIMEOUT seconds if set (> 0).
double readTimeoutSeconds(uint64_t fileBytes);

} // namespace vdbexport

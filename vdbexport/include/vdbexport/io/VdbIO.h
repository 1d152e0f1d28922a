// Reading velocity and scalar grids from .vdb files, and writing grids and text files
// atomically (temporary name + rename), with the conventions Blender needs.
#pragma once

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include "vdbexport/io/VdbCheck.h"

#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vdbexport {

namespace detail {
class SealedLeaves; // vdbexport/io/SealedLeaves.h
}

/// Grid names tried, in order, when no velocity grid name is given.
inline constexpr const char* kDefaultVelocityNames[] = {"velocity", "vel", "v"};

/// @brief Read the velocity field grid from a .vdb file.
/// @param path        the .vdb file
/// @param name        the grid to read; empty → the first of `velocity`, `vel`, `v` that exists
///                    as a Vec3 grid, else the only Vec3 grid in the file
/// @param chosenName  if non-null, receives the name of the grid that was read
/// @return the grid as a Vec3SGrid: vec3d and vec3i grids are converted (and grids stored as
///         half floats are widened by OpenVDB), keeping transform, grid class, metadata and name.
///         Values are in the field's own units (world units per unit time).
/// @throw lic::InputError naming the path and the problem: the file is missing, a directory,
///        empty, not a VDB file, corrupt or truncated; the named grid is not in the file (the
///        message lists the grids that are, with their value types); the grid is not a Vec3
///        grid; the file has no Vec3 grid; or several Vec3 grids and none of the default names.
openvdb::Vec3SGrid::Ptr readVelocityGrid(const std::string& path, const std::string& name = "",
                                         std::string* chosenName = nullptr);

/// @brief All scalar grids of a file (float, double, and float grids stored as half), as
///        FloatGrids keyed by grid name. Other grid types are skipped; the map may be empty.
/// @throw lic::InputError for a missing, empty, corrupt or truncated file (see readVelocityGrid).
std::map<std::string, openvdb::FloatGrid::Ptr> readScalarGrids(const std::string& path);

/// @brief Write grids to `path` atomically: write an unnamed temporary file in the same directory
///        (a named `path` + ".tmp-<pid>" where the file system has no O_TMPFILE), then link and
///        rename it over `path` (an OutputSet of one file), so readers never see a partial file.
///
/// Grids with active tiles are written as copies whose tiles are voxelized (Blender 3.4 renders
/// tiles as empty); the caller's grids are not modified.
/// @throw lic::InputError if the directory of `path` does not exist, is not a directory or is not
///        writable, or if `path` is a directory; lic::Error for any other failure. On failure the
///        temporary file is removed and an existing file at `path` is left untouched.
void writeVdbAtomic(const std::string& path, openvdb::GridPtrVec grids,
                    const openvdb::MetaMap& fileMetadata = {});

/// @brief Write a text file (e.g. the JSON sidecar manifest) with the same temporary-name +
///        rename scheme and the same exceptions as writeVdbAtomic.
void writeTextAtomic(const std::string& path, const std::string& text);

/// @brief Output files staged out of sight and made visible together (a bake's frames and its
///        manifest).
///
/// Each add*() writes a complete, checked file to an unnamed temporary file in the target's
/// directory (O_TMPFILE; a named `PATH.tmp-<pid>` where the file system lacks it) and records its
/// SHA-256. commit() takes an exclusive flock on each target directory, then links and renames
/// every file into place in the order added (a bake adds its frames, then its manifest: a manifest
/// on disk means its frames are): two processes committing to the same paths never interleave, so
/// the last commit wins whole. A process killed before commit() leaves no final file; with
/// O_TMPFILE no temporary either, and without it (a named PATH.tmp-PID) the next write of PATH
/// removes what a killed process left. The destructor discards whatever was not committed.
class OutputSet
{
    struct Staged
    {
        std::string path;
        int fd = -1;       ///< the unnamed temporary file
        std::string named; ///< or a named temporary
        std::string sha256;
    };

public:
    OutputSet() = default;
    ~OutputSet();
    OutputSet(const OutputSet&) = delete;
    OutputSet& operator=(const OutputSet&) = delete;

    /// A .vdb file written to its unseen temporary but not yet in a set: what writeVdb returns, so
    /// that several files can be written at once (on several threads) and added in a fixed order.
    /// Dropped without add(), it leaves nothing on disk.
    class Pending
    {
    public:
        Pending(Pending&& o) noexcept : mFile(std::move(o.mFile)) { o.mFile.fd = -1, o.mFile.named.clear(); }
        Pending& operator=(Pending&&) = delete;
        Pending(const Pending&) = delete;
        ~Pending() { discard(mFile); }

    private:
        friend class OutputSet;
        explicit Pending(Staged f) : mFile(std::move(f)) {}
        Staged mFile;
    };

    /// Write grids for `path` as addVdb does, not yet into any set. Safe to call on several threads
    /// at once for different paths (and grids only read: shared grids are fine).
    /// @throw as writeVdbAtomic.
    /// `sealed`: the records of grids whose leaves were sealed (detail::writeVdbFile).
    static Pending writeVdb(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata = {},
                            const detail::SealedLeaves* sealed = nullptr);
    /// Stage a file writeVdb wrote. @throw lic::Error if the set has a file for its path already.
    void add(Pending&& file);
    /// Stage grids for `path`, as writeVdbAtomic writes them (active tiles voxelized on copies,
    /// structure checked after writing): add(writeVdb(...)). @throw as writeVdbAtomic.
    void addVdb(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata = {},
                const detail::SealedLeaves* sealed = nullptr);
    /// Stage a text file for `path`. @throw as writeTextAtomic.
    void addText(const std::string& path, const std::string& text);
    /// SHA-256 (64 hex digits) of the bytes staged for `path`. @throw lic::Error if none.
    std::string sha256(const std::string& path) const;
    /// Move every staged file into place (see the class comment).
    /// @throw lic::Error if a link or rename fails; files committed before it stay.
    void commit();

private:
    void refuseTwice(const std::string& path) const;
    static Staged stage(const std::string& path);
    static std::string target(const Staged& f);
    static void finish(Staged& f);
    static void discard(Staged& f);
    std::vector<Staged> mFiles;
};

namespace detail {

class GridFileReader; // src/io/VdbGridReader.h

/// Check that `path` names a file we may create: its directory exists and is writable, and
/// `path` itself is not a directory. Returns the temporary name to write first (then
/// commitAtomicWrite). Shared by the VDB, text and image writers.
/// @throw lic::InputError naming the path and the problem.
std::string prepareAtomicWrite(const std::string& path);

/// Remove the temporaries of `path` (PATH.tmp-PID, PATH.tmp-PID-N) that a process no longer
/// running left behind: a process killed outright (SIGKILL) while writing on a file system without
/// O_TMPFILE cannot remove its named temporary; the next write of the same path does.
void removeStaleTemporaries(const std::string& path);

/// Grids whose compressed leaves writeVdbFile holds in memory (in-memory size, at most): a bigger
/// grid's leaves are compressed twice, both times on all cores, and streamed to the file.
constexpr std::uint64_t kWriteHoldBytes = std::uint64_t(256) << 20;

/// Write `grids` and the file metadata to `path` as openvdb::io::File::write does, byte for byte
/// but for the file's random UUID, with each float and Vec3f grid's leaves compressed once and on
/// every core (src/io/VdbWrite.cpp); grids over `holdBytes` are compressed twice, as OpenVDB does,
/// but on every core. Falls back to io::File::write for a null grid, names Archive would change
/// (empty or repeated) and trees shared by grids (instances); other grid types are written by
/// OpenVDB's own io::Archive::writeGrid within the file.
/// Errors as io::File::write's (openvdb exceptions, lic::Error); a short write is the caller's
/// to find (OutputSet::writeVdb checks the structure written).
/// Grids with sealed leaves (SealedLeaves.h: topology-only leaves, their records in `sealed`, found
/// by grid name) are written from those records.
void writeVdbFile(const std::string& path, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& fileMetadata,
                  std::uint64_t holdBytes = kWriteHoldBytes, const SealedLeaves* sealed = nullptr);

/// Flush `tmp` to disk, then rename it over `path`. Removes `tmp` and throws lic::Error on failure.
void commitAtomicWrite(const std::string& tmp, const std::string& path);

/// @brief A .vdb file opened for reading, with every failure turned into a lic::InputError
///        that names the file. Shared by readVelocityGrid, readScalarGrids and describeVdb.
///
/// The constructor checks that the path exists, is readable, is not a directory and is not
/// empty; then checks the whole file's structure (checkVdbStructure: layer 1) and, when an
/// executable is set (setReadIsolation), has a child process read it (checkInIsolatedProcess:
/// layer 2); both results are remembered for the file's (device, inode, size, mtime), so reading
/// the same unchanged file again in this process does not repeat them. Only then does OpenVDB
/// open it, without delayed loading. Every read path (fields, scalars, info, render) goes
/// through here.
class VdbReader
{
public:
    /// @throw lic::InputError if the file is missing, unreadable, a directory, empty, not a VDB
    ///        file, or truncated.
    explicit VdbReader(std::string path);
    ~VdbReader();
    VdbReader(const VdbReader&) = delete;
    VdbReader& operator=(const VdbReader&) = delete;

    const std::string& path() const { return mPath; }

    /// Name and value type (`float`, `vec3s`, …) of each grid, in file order.
    /// @throw lic::InputError if the grid headers cannot be read.
    std::vector<std::pair<std::string, std::string>> gridTypes();
    /// The grid called `name`, fully read. @throw lic::InputError if missing or unreadable.
    openvdb::GridBase::Ptr readGrid(const std::string& name);
    /// Every grid, fully read, in file order. @throw lic::InputError if unreadable.
    openvdb::GridPtrVec readAllGrids();
    /// The file-level metadata. @throw lic::InputError if unreadable.
    openvdb::MetaMap::Ptr fileMetadata();
    /// What the structural check found (grids of types licvdb does not read have a skipReason;
    /// readAllGrids leaves them out and readGrid refuses them).
    const VdbCheckResult& check() const { return mCheck; }

private:
    std::string mPath;
    VdbCheckResult mCheck;
    std::unique_ptr<openvdb::io::File> mFile;
    std::unique_ptr<GridFileReader> mGrids; ///< the grid reads (null: io::File's)
};

/// OpenVDB before 13 writes a warning on stderr ("unsupported VDB file format") when it opens a
/// file of a newer format version. checkVdbStructure has established that licvdb reads such a
/// file (version 225: OpenVDB 13), so while one is opened OpenVDB logs errors only. The level is
/// global: scopes on several threads keep it lowered until the last one ends.
class QuietNewerFormat
{
public:
    explicit QuietNewerFormat(uint32_t fileVersion);
    ~QuietNewerFormat();
    QuietNewerFormat(const QuietNewerFormat&) = delete;
    QuietNewerFormat& operator=(const QuietNewerFormat&) = delete;

private:
    bool mActive;
};

/// @brief checkVdbStructure(path) then checkInIsolatedProcess(path), each done once per unchanged
///        file (same device, inode, size and modification time) in this process.
/// @throw lic::InputError as those do.
VdbCheckResult checkedVdb(const std::string& path);

/// Forget the files checkedVdb has passed (tests).
void clearCheckedVdbCache();

/// @brief Layer 2's read of a .vdb, as the child process runs it: layer 1, then the file's
///        metadata, grid headers and every grid read through VdbReader, in this process (layer 2
///        must be off here: setReadIsolation("")). Prints "WHO: error: REASON" on stderr on failure.
/// @return the child's exit code: 0 intact, 2 refused (bad input), 1 another failure.
int readCheckMain(const std::string& path, const char* who);

/// "density (float), vel (vec3s)" — for error messages; "no grids" when empty.
std::string listGrids(const std::vector<std::pair<std::string, std::string>>& grids);

/// True for the Vec3 value types readVelocityGrid accepts (vec3s, vec3d, vec3i).
bool isVec3Type(const std::string& valueType);

} // namespace detail

} // namespace vdbexport

// Writing grids and text files atomically (an unseen temporary + rename), so that readers never
// see a partial file; the temporaries' names and their clean-up after a killed process.
#pragma once

#include <openvdb/openvdb.h>

#include <string>

namespace vdbexport {

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

namespace detail {

/// Check that `path` names a file we may create: its directory exists and is writable, and
/// `path` itself is not a directory. Returns the temporary name to write first (then
/// commitAtomicWrite). Shared by the VDB, text and image writers.
/// @throw lic::InputError naming the path and the problem.
std::string prepareAtomicWrite(const std::string& path);

/// Remove the temporaries of `path` (PATH.tmp-PID, PATH.tmp-PID-N) that a process no longer
/// running left behind: a process killed outright (SIGKILL) while writing on a file system without
/// O_TMPFILE cannot remove its named temporary; the next write of the same path does.
void removeStaleTemporaries(const std::string& path);

/// Test seam: $LICVDB_TEST_NO_O_TMPFILE=1 makes every writer that would open an unnamed file
/// (O_TMPFILE: OutputSet's staged files, a loop's spool) use a named one instead, as on a file
/// system without O_TMPFILE. Read on every call.
bool noTmpfile();

/// Flush `tmp` to disk, then rename it over `path`. Removes `tmp` and throws lic::Error on failure.
void commitAtomicWrite(const std::string& tmp, const std::string& path);

} // namespace detail

} // namespace vdbexport

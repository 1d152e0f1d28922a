// A .vdb file opened for reading, checked first (ReadCheck.h), with every failure a lic::InputError
// that names the file.
#pragma once

#include "vdbexport/io/VdbCheck.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vdbexport::detail {

class GridFileReader; // src/io/VdbGridReader.h

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

/// "density (float), vel (vec3s)" — for error messages; "no grids" when empty.
std::string listGrids(const std::vector<std::pair<std::string, std::string>>& grids);

} // namespace vdbexport::detail

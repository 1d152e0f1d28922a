// Reading velocity and scalar grids from .vdb files, and writing grids and text files
// atomically (temporary name + rename), with the conventions Blender needs.
#pragma once

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vdbexport {

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

/// @brief Write grids to `path` atomically: write `path` + ".tmp-<pid>" in the same directory,
///        then rename it over `path`, so readers never see a partial file.
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

/// Flush `tmp` to disk, then rename it over `path`. Removes `tmp` and throws lic::Error on failure.
void commitAtomicWrite(const std::string& tmp, const std::string& path);

/// @brief A .vdb file opened for reading, with every failure turned into a lic::InputError
///        that names the file. Shared by readVelocityGrid, readScalarGrids and describeVdb.
///
/// The constructor checks that the path exists, is readable, is not a directory and is not
/// empty; then reads the file header and table of grids with bounds-checked reads (so a file cut
/// short anywhere, even one byte before its end, is reported as truncated: OpenVDB alone reads
/// a shortened last grid without complaint); then opens it with OpenVDB, without delayed loading.
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

private:
    std::string mPath;
    std::unique_ptr<openvdb::io::File> mFile;
};

/// "density (float), vel (vec3s)" — for error messages; "no grids" when empty.
std::string listGrids(const std::vector<std::pair<std::string, std::string>>& grids);

/// True for the Vec3 value types readVelocityGrid accepts (vec3s, vec3d, vec3i).
bool isVec3Type(const std::string& valueType);

} // namespace detail

} // namespace vdbexport

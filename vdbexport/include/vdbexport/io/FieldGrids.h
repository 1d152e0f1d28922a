// Reading a velocity field and scalar grids from a .vdb file: Vec3 grids of any precision (or
// split components `vel.x`, `vel.y`, `vel.z`) as one Vec3SGrid, float and double grids as FloatGrids.
#pragma once

#include <openvdb/openvdb.h>

#include <map>
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

namespace detail {

/// True for the Vec3 value types readVelocityGrid accepts (vec3s, vec3d, vec3i).
bool isVec3Type(const std::string& valueType);

} // namespace detail

} // namespace vdbexport

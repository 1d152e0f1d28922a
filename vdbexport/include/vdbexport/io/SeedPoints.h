// Explicit spot centres (recipe `input.seeds`, `--seeds FILE`): a file of world-space points that
// replaces the spot distribution.
#pragma once

#include <openvdb/openvdb.h>

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace vdbexport {

/// The most points a seeds file may hold (a spot per output voxel of a 370³ box; far more
/// spots than any line picture can show).
inline constexpr std::size_t kMaxSeedPoints = 50'000'000;

/// @brief Read the spot centres of `path`, in WORLD units: a `.npy` file (shape (N, 3), float32
///        or float64, either byte order, C or Fortran order), or, for any other extension, text
///        with three numbers `x y z` per line (separated by spaces, tabs or commas; `#` starts a
///        comment; blank lines are skipped).
/// @throw lic::InputError naming the file and the problem: missing or unreadable, wrong .npy
///        shape or dtype, a text line that is not three numbers (with its line number), a NaN or
///        infinite coordinate (with its row or line), no points, more than kMaxSeedPoints.
std::vector<openvdb::Vec3d> readSeedPoints(const std::string& path);

/// The points of a .npy file held in memory (as readSeedPoints). `source` names it in messages.
std::vector<openvdb::Vec3d> parseSeedNpy(std::string_view bytes, const std::string& source);

/// The points of a text file held in memory (as readSeedPoints). `source` names it in messages.
std::vector<openvdb::Vec3d> parseSeedText(std::string_view text, const std::string& source);

} // namespace vdbexport

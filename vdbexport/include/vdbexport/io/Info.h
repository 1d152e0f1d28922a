// `licvdb info`: describe the grids and metadata of a .vdb file, as JSON or as text.
#pragma once

#include <nlohmann/json.hpp>

#include <string>

namespace vdbexport {

/// @brief Describe a .vdb file. Every grid is read fully (not just its header).
///
/// Result:
/// ```
/// {"path": "...", "file_metadata": {...},
///  "grids": [{"name", "value_type" ("float", "vec3s", …), "class" ("fog volume", "level set",
///             "unknown", …), "active_voxels" (tiles included), "active_tiles", "leaf_nodes",
///             "index_bbox": [[x,y,z],[x,y,z]] (inclusive, index space; null if no active value),
///             "world_bbox": [[x,y,z],[x,y,z]] (world bounds of the active voxels' extents:
///                           index bbox min−0.5 … max+0.5 through the transform; null if empty),
///             "voxel_size": [x,y,z] (world units),
///             "memory_bytes" (in memory, as loaded),
///             "value_range": [min,max] over active finite values (magnitude for vector grids;
///                            null for empty, mask and point grids),
///             "non_finite_values" (active values that are NaN or ±inf; vector: any component),
///             "metadata": {name: value}}]}
/// ```
/// Metadata values become JSON numbers, bools and strings; vectors become arrays and matrices
/// arrays of rows; a string that parses as a JSON object (e.g. `licvdb_recipe`) is embedded as
/// that object. The grid's `name` and `class` and the `file_*` statistics OpenVDB adds on write
/// are reported as fields, not repeated under "metadata".
/// @throw lic::InputError for a missing, empty, corrupt or truncated file.
nlohmann::json describeVdb(const std::string& path);

/// @brief Human-readable multi-line text of describeVdb's result: the path and file metadata,
///        an aligned table of grids, then per grid its bounding boxes and metadata. Long values
///        (such as embedded JSON recipes) are shown compactly on one line, truncated to about
///        100 characters with "…".
std::string formatInfo(const nlohmann::json& description);

} // namespace vdbexport

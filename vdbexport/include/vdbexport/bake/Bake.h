// A whole bake: recipe → field → LIC → grids → .vdb + JSON manifest, written atomically.
#pragma once

#include "vdbexport/bake/Recipe.h"

#include "lic/util/Progress.h"

#include <nlohmann/json.hpp>

#include <string>

namespace vdbexport {

/// The file of frame `frame` (1-based) of a bake of `frames` frames: OUT.vdb itself for a still,
/// OUT_0001.vdb … for a loop (1-based, 4 digits).
std::string framePath(const std::string& vdbPath, int frame, int frames);

/// The ending of a bake's sidecar manifest: OUT.vdb → OUT.licvdb.json (older bakes: OUT.json).
inline constexpr const char* manifestSuffix = ".licvdb.json";

/// The sidecar manifest path of a bake: OUT.vdb → OUT.licvdb.json, one for a whole sequence
/// (OUT_0001.vdb … share OUT.licvdb.json); a path not ending in .vdb gets the suffix appended.
/// Every place that names a bake's manifest goes through here.
std::string manifestPath(const std::string& vdbPath);

/// @throw lic::InputError if a file the bake would write (a frame or the manifest) is the file
/// at `path` under any name (`what` says what it is: "the input field", "the recipe"), so a bake
/// never replaces its own inputs.
void checkNotOverwritten(const Recipe& recipe, const std::string& path, const std::string& what);

/// Run the bake described by `recipe` (validated here, paths included): read the field, convolve,
/// normalise, and write `recipe.output.path` plus its manifest, both atomically (a failed bake
/// leaves neither). Returns the summary that `licvdb bake --json` prints: output paths, voxel
/// counts, streamlines, samples per voxel and per-stage seconds.
/// @throw lic::InputError for bad input or recipe values (including features a later release
///        adds: spots, ROI, width, colour, exp kernel, animation); lic::Error on runtime failure.
nlohmann::json bake(const Recipe& recipe, lic::Progress& progress = lic::nullProgress());

} // namespace vdbexport

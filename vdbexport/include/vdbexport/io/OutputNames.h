// The names of the files a bake writes: a still OUT.vdb, numbered frames OUT_0001.vdb … of a loop
// or an unsteady sequence, and the sidecar manifest OUT.licvdb.json. Every place that names a
// bake's output goes through here.
#pragma once

#include <string>

namespace vdbexport {

/// Frame `frame` of OUT.vdb: OUT_0012.vdb (at least 4 digits; a path not ending in .vdb keeps its
/// whole name as the stem). Loops number from 1; unsteady sequences use the field's frame numbers.
std::string numberedPath(const std::string& vdbPath, int frame);

/// The file of frame `frame` (1-based) of a bake of `frames` frames: OUT.vdb itself for a still,
/// numberedPath() for a loop.
std::string framePath(const std::string& vdbPath, int frame, int frames);

/// The ending of a bake's sidecar manifest: OUT.vdb → OUT.licvdb.json (older bakes: OUT.json).
inline constexpr const char* manifestSuffix = ".licvdb.json";

/// The sidecar manifest path of a bake: OUT.vdb → OUT.licvdb.json, one for a whole sequence
/// (OUT_0001.vdb … share OUT.licvdb.json); a path not ending in .vdb gets the suffix appended.
std::string manifestPath(const std::string& vdbPath);

} // namespace vdbexport

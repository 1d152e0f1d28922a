// Unsteady field sequences: a file-name pattern with the frame number in it
// (`cache/data/fluid_data_####.vdb`, `vel.%04d.vdb`), a frame range, and the files it names.
#pragma once

#include "vdbexport/io/FieldSpec.h"

#include <string>
#include <vector>

namespace vdbexport {

/// True if `path` holds a frame-number placeholder: a run of `#` (its length is the zero-padded
/// width) or a printf conversion `%d` / `%0Nd`.
bool isFramePattern(const std::string& path);

/// The file of frame `frame` of a pattern (`####` → 0012; `%04d` → 0012; `%d` → 12).
/// @throw lic::InputError if `pattern` has no placeholder or more than one.
std::string expandFramePattern(const std::string& pattern, int frame);

/// The frames of a sequence bake, in order, with their files.
struct FieldFrames
{
    std::vector<int> numbers;
    std::vector<std::string> paths;
};

/// The frames `field` names: field.frames with its pattern, or (no frames given) every frame of
/// the pattern found on disk, which must then be a contiguous run.
/// @throw lic::InputError for frames without a pattern, a pattern without frames on disk, missing
///        frames (naming the first and how many), or a range that is not contiguous on disk.
FieldFrames resolveFieldFrames(const FieldSpec& field);

} // namespace vdbexport

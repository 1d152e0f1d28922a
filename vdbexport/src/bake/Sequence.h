// An unsteady bake: a field sequence in, one carried-texture LIC frame per field frame out.
#pragma once

#include "vdbexport/bake/Recipe.h"

#include "lic/util/Progress.h"

#include <nlohmann/json.hpp>

#include <string>

namespace vdbexport::pipeline {

/// Bake every frame of the recipe's field sequence (vdbexport::isSequenceBake): frames
/// OUT_FFFF.vdb numbered as the field's, one manifest, all committed together at the end.
/// Returns the summary `licvdb bake --json` prints (per-frame counters and seconds).
/// @throw lic::InputError for bad input (missing frames, frames that disagree, …); lic::Cancelled.
nlohmann::json bakeSequence(const Recipe& recipe, lic::Progress& progress);

} // namespace vdbexport::pipeline

// A whole bake: recipe → field → LIC → grids → .vdb + JSON manifest, written atomically.
#pragma once

#include "vdbexport/bake/Outputs.h"
#include "vdbexport/bake/Recipe.h"
#include "vdbexport/io/OutputNames.h"

#include "lic/util/Progress.h"

#include <nlohmann/json.hpp>

namespace vdbexport {

/// Run the bake described by `recipe` (validated here, paths included): read the field, convolve,
/// normalise, and write `recipe.output.path` plus its manifest, both atomically (a failed bake
/// leaves neither). A still, a cyclic loop (animation.frames > 1) or an unsteady sequence (a field
/// frame pattern); under mpirun, shared over the ranks. At most recipe.threads threads (0 = all
/// cores) in every stage. Returns the summary that `licvdb bake --json` prints: output paths,
/// voxel counts, streamlines, samples per voxel and per-stage seconds.
/// @throw lic::InputError for bad input or recipe values; lic::Cancelled; lic::Error on runtime
///        failure.
nlohmann::json bake(const Recipe& recipe, lic::Progress& progress = lic::nullProgress());

} // namespace vdbexport

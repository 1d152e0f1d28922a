// The files a bake writes, and the rule that it never writes over one of its inputs.
#pragma once

#include "vdbexport/bake/Recipe.h"
#include "vdbexport/io/OutputNames.h"

#include <string>
#include <vector>

namespace vdbexport {

/// True if the recipe bakes an unsteady sequence (field.frames, or a pattern path).
bool isSequenceBake(const Recipe& recipe);

/// Every file the bake of `recipe` writes: its frames (one still, a loop's, or an unsteady
/// sequence's when the field's frames can be resolved) and its manifest.
std::vector<std::string> bakeOutputs(const Recipe& recipe);

/// @throw lic::InputError if a file the bake would write (a frame or the manifest) is the file
/// at `path` under any name (`what` says what it is: "the input field", "the recipe"), so a bake
/// never replaces its own inputs.
void checkNotOverwritten(const Recipe& recipe, const std::string& path, const std::string& what);

} // namespace vdbexport

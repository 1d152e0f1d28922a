#include "vdbexport/bake/Outputs.h"

#include "vdbexport/io/FieldSequence.h"

#include "lic/util/Error.h"

#include <filesystem>

namespace vdbexport {

namespace fs = std::filesystem;

bool isSequenceBake(const Recipe& recipe) { return recipe.field.frames.has_value() || isFramePattern(recipe.field.path); }

std::vector<std::string> bakeOutputs(const Recipe& recipe)
{
    std::vector<std::string> outputs{manifestPath(recipe.output.path)};
    if (isSequenceBake(recipe)) {
        try {
            for (int f : resolveFieldFrames(recipe.field).numbers) outputs.push_back(numberedPath(recipe.output.path, f));
        } catch (const lic::InputError&) {
            // the bake itself reports a sequence it cannot resolve
        }
    } else {
        for (int f = 1; f <= recipe.animation.frames; ++f)
            outputs.push_back(framePath(recipe.output.path, f, recipe.animation.frames));
    }
    return outputs;
}

void checkNotOverwritten(const Recipe& recipe, const std::string& path, const std::string& what)
{
    if (path.empty()) return;
    std::error_code ec;
    const fs::path input = fs::weakly_canonical(path, ec);
    if (ec) return; // cannot be resolved: reading it will report the problem
    for (const auto& out : bakeOutputs(recipe)) {
        std::error_code e1, e2;
        const bool same = fs::equivalent(path, out, e1) || fs::weakly_canonical(out, e2) == input;
        if (same && !e2) {
            throw lic::InputError("the bake would overwrite " + what + " \"" + path + "\" with \"" + out +
                                  "\"; choose another --out");
        }
    }
}

} // namespace vdbexport

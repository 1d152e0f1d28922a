// libFuzzer target: parseRecipe (JSON → Recipe → validate) on arbitrary text; a recipe that
// parses must serialise and parse back to the same recipe.
// Any exception other than lic::InputError, any crash or sanitizer report is a finding.
#include "vdbexport/bake/Recipe.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const vdbexport::Recipe r = vdbexport::parseRecipe(text, "fuzz.json");
        const vdbexport::Recipe back = vdbexport::parseRecipe(r.toJson().dump(), "roundtrip");
        if (!(back == r)) std::abort();
    } catch (const lic::InputError&) {
    }
    return 0;
}

// Each engine checks its own settings (bake/EngineKeys.cpp): a `lic` key set to other than its
// default that the chosen engine does not read (lic::EngineInfo::keys), lic.decay without the exp
// kernel and lic.tolerance without rk45 are refused with a message that names the key, the engine
// and the keys it reads; every key of the recipe's `lic` section is covered, and the recipes
// shipped in examples/ pass.
#include "vdbexport/bake/Recipe.h"

#include "bake/Plan.h"

#include "lic/engine/Engine.h"
#include "lic/util/Error.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <string>

using nlohmann::json;
using vdbexport::Recipe;
using vdbexport::pipeline::checkEngineKeys;

namespace {

/// A recipe with these `lic` keys and input type.
Recipe recipeWith(const json& lic, const std::string& input = "noise")
{
    return Recipe::fromJson(json{{"lic", lic}, {"input", {{"type", input}}}});
}

/// The InputError message of checkEngineKeys(r), or "" when it passes.
std::string refusal(const Recipe& r)
{
    try {
        checkEngineKeys(r);
    } catch (const lic::InputError& e) {
        return e.what();
    }
    return "";
}

bool reads(const lic::EngineInfo& e, const std::string& key)
{
    return std::find(e.keys.begin(), e.keys.end(), key) != e.keys.end();
}

// A value other than the default for every `lic` key but `engine`, with the choice it is read
// under (decay: exp kernel; tolerance: rk45).
const std::map<std::string, json>& nonDefaults()
{
    static const std::map<std::string, json> all{
        {"kernel", {{"kernel", "exp"}}},
        {"length", {{"length", 10}}},
        {"step", {{"step", 0.25}}},
        {"decay", {{"kernel", "exp"}, {"decay", 0.8}}},
        {"integrator", {{"integrator", "rk45"}}},
        {"tolerance", {{"integrator", "rk45"}, {"tolerance", 1e-4}}},
        {"min_hits", {{"min_hits", 3}}},
        {"brick", {{"brick", 32}}},
    };
    return all;
}

} // namespace

TEST(EngineKeys, EveryLicKeyIsCheckedForEveryEngineAndInput)
{
    // The cases cover the recipe's `lic` keys exactly: a new key needs a case here (and a line in
    // EngineKeys.cpp, or every engine that does not list it would accept it silently).
    const json resolved = Recipe{}.toJson();
    std::vector<std::string> keys;
    for (const auto& [key, value] : resolved.at("lic").items())
        if (key != "engine") keys.push_back(key);
    std::vector<std::string> cased;
    for (const auto& [key, lic] : nonDefaults()) cased.push_back(key);
    std::sort(keys.begin(), keys.end());
    EXPECT_EQ(keys, cased);

    for (const lic::EngineInfo& e : lic::engines()) {
        for (const std::string input : {"noise", "spots"}) {
            if (input == "spots" ? e.spotBricks == nullptr : e.noiseBricks == nullptr) continue;
            EXPECT_EQ(refusal(recipeWith({{"engine", e.name}}, input)), "") << e.name << ", " << input;
            for (const auto& [key, lic] : nonDefaults()) {
                json withEngine = lic;
                withEngine["engine"] = e.name;
                const std::string msg = refusal(recipeWith(withEngine, input));
                SCOPED_TRACE(std::string(e.name) + ", " + input + ", lic." + key);
                if (reads(e, key)) {
                    EXPECT_EQ(msg, "");
                } else {
                    EXPECT_NE(msg.find("lic." + key + " (--"), std::string::npos) << msg;
                    EXPECT_NE(msg.find("the \"" + std::string(e.name) + "\" engine does not use it"), std::string::npos) << msg;
                    EXPECT_NE(msg.find("(it reads lic." + std::string(e.keys.front())), std::string::npos) << msg;
                }
            }
        }
    }
}

TEST(EngineKeys, MinHitsWithSplatNamesTheEngineAndWhatItReads)
{
    EXPECT_EQ(refusal(recipeWith({{"engine", "splat"}, {"min_hits", 3}}, "spots")),
              "lic.min_hits (--min-hits): the \"splat\" engine does not use it (it reads lic.kernel, lic.length, "
              "lic.step, lic.decay, lic.integrator, lic.tolerance, lic.brick); remove it, or choose an engine that "
              "reads it (lic.engine, --engine): fast");
    // The fast engine reads it, for either input; naive does not, and points to fast.
    EXPECT_EQ(refusal(recipeWith({{"engine", "fast"}, {"min_hits", 3}}, "spots")), "");
    EXPECT_EQ(refusal(recipeWith({{"engine", "fast"}, {"min_hits", 1}})), "");
    EXPECT_EQ(refusal(recipeWith({{"engine", "naive"}, {"min_hits", 1}})),
              "lic.min_hits (--min-hits): the \"naive\" engine does not use it (it reads lic.kernel, lic.length, "
              "lic.step, lic.decay, lic.integrator, lic.tolerance, lic.brick); remove it, or choose an engine that "
              "reads it (lic.engine, --engine): fast");
}

TEST(EngineKeys, AutoIsCheckedAgainstTheEngineItPicks)
{
    // auto = splat for spots (no min_hits), fast for noise (min_hits).
    EXPECT_EQ(refusal(recipeWith({{"min_hits", 3}}, "spots")),
              "lic.min_hits (--min-hits): the \"splat\" engine (what lic.engine \"auto\" picks for spot input) does "
              "not use it (it reads lic.kernel, lic.length, lic.step, lic.decay, lic.integrator, lic.tolerance, "
              "lic.brick); remove it, or choose an engine that reads it (lic.engine, --engine): fast");
    EXPECT_EQ(refusal(recipeWith({{"min_hits", 3}}, "noise")), "");
}

TEST(EngineKeys, ADefaultValueCountsAsUnset)
{
    // A key given with its default value asks for what the engine does anyway: a recipe a bake
    // recorded (every key, resolved) can be baked again.
    EXPECT_EQ(refusal(recipeWith({{"engine", "splat"}, {"min_hits", 2}, {"decay", 0.9}, {"tolerance", 1e-3}}, "spots")), "");
    Recipe recorded;
    recorded.input.type = "spots";
    recorded.lic.engine = "splat";
    EXPECT_EQ(refusal(Recipe::fromJson(recorded.toJson())), "");
}

TEST(EngineKeys, DecayNeedsTheExpKernelAndToleranceRk45)
{
    EXPECT_EQ(refusal(recipeWith({{"decay", 0.8}})),
              "lic.decay (--decay): the \"box\" kernel does not use it (only lic.kernel \"exp\" reads it); remove "
              "it, or set lic.kernel \"exp\" (--kernel exp)");
    EXPECT_EQ(refusal(recipeWith({{"kernel", "exp"}, {"decay", 0.8}})), "");
    EXPECT_EQ(refusal(recipeWith({{"tolerance", 1e-4}}, "spots")),
              "lic.tolerance (--tolerance): the \"rk4\" integrator does not use it (only lic.integrator \"rk45\" "
              "reads it); remove it, or set lic.integrator \"rk45\" (--integrator rk45)");
    EXPECT_EQ(refusal(recipeWith({{"integrator", "rk45"}, {"tolerance", 1e-4}}, "spots")), "");
}

TEST(EngineKeys, ShippedRecipesPass)
{
    // The examples (README, the gallery) are real recipes: none sets a key its engine ignores.
    namespace fs = std::filesystem;
    int n = 0;
    for (const char* dir : {"examples/recipes", "examples/gallery"}) {
        for (const auto& entry : fs::directory_iterator(fs::path(LICVDB_SOURCE_DIR) / dir)) {
            if (entry.path().extension() != ".json") continue;
            SCOPED_TRACE(entry.path().string());
            EXPECT_EQ(refusal(vdbexport::loadRecipeFile(entry.path().string())), "");
            ++n;
        }
    }
    EXPECT_GE(n, 20);
}

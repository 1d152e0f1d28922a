// Each engine checks its own settings (pbrt-v4's ParameterDictionary::ReportUnused): a recipe
// `lic` key that nothing will read is refused, naming the engine and the keys it reads. The keys
// an engine reads are its row's lic::EngineInfo::keys; lic.decay (exp kernel) and lic.tolerance
// (rk45) are read only under those choices, by every engine.
//
// A key counts as set when its value differs from the default (LicSpec{}), not when the recipe
// or a flag names it: a bake records the fully resolved recipe (every key, with its value) and
// RecipeFlags::apply() re-reads flags through that same resolved JSON, so whether a key was
// written is not known here; and a recorded recipe baked again must stay valid. So `"min_hits":
// 2` with the splat engine passes (it asks for what the engine does anyway).
#include "Plan.h"

#include "lic/engine/Engine.h"
#include "lic/util/Error.h"

#include <string>
#include <string_view>
#include <vector>

namespace vdbexport::pipeline {

namespace {

/// One `lic` key an engine may read, and whether a recipe sets it (its value is not the default).
struct LicKey
{
    std::string_view name;
    bool (*set)(const LicSpec& lic, const LicSpec& defaults);
};

// Every key of the recipe's `lic` section but `engine` (Recipe.h LicSpec).
constexpr LicKey kLicKeys[] = {
    {"kernel", [](const LicSpec& l, const LicSpec& d) { return l.kernel != d.kernel; }},
    {"length", [](const LicSpec& l, const LicSpec& d) { return l.length != d.length; }},
    {"step", [](const LicSpec& l, const LicSpec& d) { return l.step != d.step; }},
    {"decay", [](const LicSpec& l, const LicSpec& d) { return l.decay != d.decay; }},
    {"integrator", [](const LicSpec& l, const LicSpec& d) { return l.integrator != d.integrator; }},
    {"tolerance", [](const LicSpec& l, const LicSpec& d) { return l.tolerance != d.tolerance; }},
    {"min_hits", [](const LicSpec& l, const LicSpec& d) { return l.minHits != d.minHits; }},
    {"brick", [](const LicSpec& l, const LicSpec& d) { return l.brick != d.brick; }},
};

/// A key read only under one choice of another key, whatever the engine.
struct ChoiceKey
{
    std::string_view key;    ///< e.g. "decay"
    std::string_view by;     ///< the key that chooses, e.g. "kernel"
    std::string_view choice; ///< the value under which `key` is read, e.g. "exp"
    const std::string& (*value)(const LicSpec&); ///< the recipe's value of `by`
};

constexpr ChoiceKey kChoiceKeys[] = {
    {"decay", "kernel", "exp", [](const LicSpec& l) -> const std::string& { return l.kernel; }},
    {"tolerance", "integrator", "rk45", [](const LicSpec& l) -> const std::string& { return l.integrator; }},
};

const LicKey* findKey(std::string_view name)
{
    for (const LicKey& k : kLicKeys)
        if (k.name == name) return &k;
    return nullptr;
}

bool reads(const lic::EngineInfo& engine, std::string_view key)
{
    for (std::string_view k : engine.keys)
        if (k == key) return true;
    return false;
}

/// "lic.min_hits (--min-hits)": the key and the bake flag that sets it.
std::string keyAndFlag(std::string_view key)
{
    std::string flag(key);
    for (char& c : flag)
        if (c == '_') c = '-';
    return "lic." + std::string(key) + " (--" + flag + ")";
}

std::string joined(const std::vector<std::string>& items, const char* sep)
{
    std::string out;
    for (const std::string& s : items) out += (out.empty() ? "" : sep) + s;
    return out;
}

} // namespace

void checkEngineKeys(const Recipe& recipe)
{
    const bool spots = recipe.input.type == "spots";
    const lic::EngineInfo& engine = lic::engineInfo(lic::chooseEngine(recipe.lic.engine, spots));
    const LicSpec defaults;
    for (std::string_view k : engine.keys) {
        if (!findKey(k)) {
            throw lic::Error("the engine table's row for \"" + std::string(engine.name) + "\" names lic." +
                             std::string(k) + ", a key bake/EngineKeys.cpp does not know");
        }
    }

    std::vector<std::string> unread, named, readBy, others;
    for (const LicKey& k : kLicKeys) {
        if (!k.set(recipe.lic, defaults) || reads(engine, k.name)) continue;
        unread.emplace_back(k.name);
        named.push_back(keyAndFlag(k.name));
    }
    if (!unread.empty()) {
        for (std::string_view k : engine.keys) readBy.push_back("lic." + std::string(k));
        // Engines that take this input and read every one of the keys.
        for (const lic::EngineInfo& e : lic::engines()) {
            if (spots ? e.spotBricks == nullptr : e.noiseBricks == nullptr) continue;
            bool all = true;
            for (const std::string& k : unread) all = all && reads(e, k);
            if (all) others.emplace_back(e.name);
        }
        const bool one = unread.size() == 1;
        const std::string it = one ? "it" : "them";
        std::string msg = joined(named, ", ") + ": the \"" + engine.name + "\" engine";
        if (recipe.lic.engine == "auto")
            msg += std::string(" (what lic.engine \"auto\" picks for ") + (spots ? "spot" : "noise") + " input)";
        msg += " does not use " + it + " (it reads " + joined(readBy, ", ") + "); remove " + it;
        if (!others.empty())
            msg += ", or choose an engine that reads " + it + " (lic.engine, --engine): " + joined(others, ", ");
        throw lic::InputError(msg);
    }
    for (const ChoiceKey& c : kChoiceKeys) {
        if (!findKey(c.key)->set(recipe.lic, defaults) || c.value(recipe.lic) == c.choice) continue;
        const std::string by(c.by), choice(c.choice);
        throw lic::InputError(keyAndFlag(c.key) + ": the \"" + c.value(recipe.lic) + "\" " + by + " does not use it (only lic." +
                              by + " \"" + choice + "\" reads it); remove it, or set lic." + by + " \"" + choice + "\" (--" +
                              by + " " + choice + ")");
    }
}

} // namespace vdbexport::pipeline

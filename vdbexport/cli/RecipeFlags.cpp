#include "RecipeFlags.h"

#include <lic/util/Error.h>


namespace vdbexport::cli {

namespace {

/// The parts of key path "input.surface": "input", "surface".
std::vector<std::string> splitKey(const std::string& key)
{
    std::vector<std::string> parts;
    std::size_t begin = 0;
    while (true) {
        const std::size_t dot = key.find('.', begin);
        parts.push_back(key.substr(begin, dot - begin));
        if (dot == std::string::npos) return parts;
        begin = dot + 1;
    }
}

/// Set key path `key` of `recipe` to `value`; a null (absent) section on the way becomes an object.
void setKey(nlohmann::json& recipe, const std::string& key, nlohmann::json value)
{
    nlohmann::json* node = &recipe;
    for (const std::string& part : splitKey(key)) node = &(*node)[part];
    *node = std::move(value);
}

} // namespace

bool isAbsent(const nlohmann::json& recipe, const std::string& key)
{
    const nlohmann::json* node = &recipe;
    for (const std::string& part : splitKey(key)) {
        if (!node->is_object() || !node->contains(part)) return true;
        node = &(*node)[part];
    }
    return node->is_null();
}

CLI::Option* RecipeFlags::text(const std::string& names, const char* key, const std::string& help,
                               Convert<std::string> convert)
{
    auto value = std::make_shared<std::string>();
    CLI::Option* o = mCmd.add_option(names, *value, help);
    add(o, key, [value] { return !value->empty(); }, value, std::move(convert));
    return o;
}

CLI::Option* RecipeFlags::flag(const std::string& names, const char* key, const std::string& help)
{
    auto value = std::make_shared<bool>(false);
    CLI::Option* o = mCmd.add_flag(names, *value, help);
    add<bool>(o, key, [value] { return *value; }, value, {});
    return o;
}

void RecipeFlags::needsSection(const char* section, std::string message)
{
    Binding& b = mBindings.back();
    b.value = [section = std::string(section), message = std::move(message),
               value = std::move(b.value)](const nlohmann::json& recipe) {
        if (isAbsent(recipe, section)) throw lic::InputError(message);
        return value(recipe);
    };
}

bool RecipeFlags::given(const std::string& name) const
{
    for (const Binding& b : mBindings)
        if (b.option->check_name(name)) return b.given();
    return false;
}

Recipe RecipeFlags::apply(const Recipe& recipe) const
{
    nlohmann::json j = recipe.toJson();
    for (const Binding& b : mBindings)
        if (b.given()) setKey(j, b.key, b.value(j));
    return Recipe::fromJson(j, "the command line");
}

} // namespace vdbexport::cli

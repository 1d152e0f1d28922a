// Command-line flags bound once to recipe keys: an optional overlay of the recipe.
#pragma once

#include "vdbexport/bake/Recipe.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vdbexport::cli {

/// @brief The flags of `licvdb bake` that set recipe values. Each flag is bound once, to its key
///        path in the recipe JSON ("lic.length", "roi.range"); apply() writes the value of every
///        given flag under its key, in the order the flags were added, and reads the recipe back:
///        the one place where flags override a recipe. A key inside an absent section (`roi`,
///        `width`, `color`, `input.surface`) creates it with its defaults.
///
/// A value that needs parsing beyond CLI11's conversion (a list "X,Y,Z", a frame range) is
/// parsed in apply(), after the recipe file was read, so its errors come in the same order as
/// the recipe's. The object must outlive the parse (CLI11 writes into it) and is not movable.
class RecipeFlags
{
public:
    /// Turns a flag's value into its key's JSON value, given the recipe JSON so far.
    /// @throw lic::InputError naming the flag, its value and what was expected.
    template <class T>
    using Convert = std::function<nlohmann::json(const T& value, const nlohmann::json& recipe)>;

    explicit RecipeFlags(CLI::App& cmd) : mCmd(cmd) {}
    RecipeFlags(const RecipeFlags&) = delete;
    RecipeFlags& operator=(const RecipeFlags&) = delete;

    /// `names VALUE` (CLI11 converts VALUE to T and shows T in the help); when given, sets `key`
    /// to `convert(VALUE)` (default: VALUE itself).
    template <class T>
    CLI::Option* option(const std::string& names, const char* key, const std::string& help, Convert<T> convert = {})
    {
        auto value = std::make_shared<T>();
        CLI::Option* o = mCmd.add_option(names, *value, help);
        add(o, key, [o] { return o->count() > 0; }, std::move(value), std::move(convert));
        return o;
    }

    /// A free-text value (a path, a scalar name, a list): like option<std::string>, but an empty
    /// value counts as not given.
    CLI::Option* text(const std::string& names, const char* key, const std::string& help,
                      Convert<std::string> convert = {});

    /// A switch: when set, sets `key` to true.
    CLI::Option* flag(const std::string& names, const char* key, const std::string& help);

    /// Bind an option added elsewhere to `variable` (its CLI11 variable): when given, sets `key`.
    template <class T>
    void bind(CLI::Option* option, const char* key, const T& variable)
    {
        mBindings.push_back({option, key, [option] { return option->count() > 0; },
                             [&variable](const nlohmann::json&) { return nlohmann::json(variable); }});
    }

    /// The flag added last sets a key inside optional section `section` ("color",
    /// "input.surface") that must already exist (from the recipe or an earlier flag); otherwise
    /// apply() throws lic::InputError(`message`).
    void needsSection(const char* section, std::string message);

    /// Whether the flag named `name` ("--roi-range") was given (for text(): and not empty).
    bool given(const std::string& name) const;

    /// `recipe` with every given flag applied.
    /// @throw lic::InputError from a flag's conversion or a missing section.
    Recipe apply(const Recipe& recipe) const;

private:
    struct Binding
    {
        CLI::Option* option;
        std::string key;
        std::function<bool()> given;
        std::function<nlohmann::json(const nlohmann::json& recipe)> value;
    };

    template <class T>
    void add(CLI::Option* o, const char* key, std::function<bool()> given, std::shared_ptr<T> value,
             Convert<T> convert)
    {
        mBindings.push_back({o, key, std::move(given), [value, convert](const nlohmann::json& recipe) {
                                 return convert ? convert(*value, recipe) : nlohmann::json(*value);
                             }});
    }

    CLI::App& mCmd;
    std::vector<Binding> mBindings;
};

/// Whether the recipe JSON has no value (null or no key) at key path `key` ("input.surface").
bool isAbsent(const nlohmann::json& recipe, const std::string& key);

} // namespace vdbexport::cli

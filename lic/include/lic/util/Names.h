// Names of enum values: one table per enum gives both directions, and the error for an unknown
// name lists the table, so a new value is added in one place.
#pragma once

#include "lic/util/Error.h"

#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace lic {

/// One row of an enum's name table. The first row of a value is its name; later rows of the same
/// value are aliases, accepted but not listed. `note` is shown in parentheses in the list.
template<typename E>
struct EnumName
{
    E value;
    std::string_view name;
    std::string_view note = {};
};

/// The listed names of a table (aliases left out), in order: e.g. a recipe key's allowed values.
template<typename E>
std::vector<std::string> listedNames(std::span<const EnumName<E>> table)
{
    std::vector<std::string> out;
    for (std::size_t i = 0; i < table.size(); ++i) {
        bool alias = false;
        for (std::size_t j = 0; j < i; ++j) alias = alias || table[j].value == table[i].value;
        if (!alias) out.emplace_back(table[i].name);
    }
    return out;
}

/// "a, b or c" of the table's listed names (aliases left out), each followed by " (note)" if any.
template<typename E>
std::string listNames(std::span<const EnumName<E>> table)
{
    const std::vector<std::string> names = listedNames(table);
    std::string out;
    for (std::size_t i = 0; i < names.size(); ++i) {
        if (i > 0) out += i + 1 == names.size() ? " or " : ", ";
        out += names[i];
        for (const auto& row : table)
            if (row.name == names[i] && !row.note.empty()) out += " (" + std::string(row.note) + ")";
    }
    return out;
}

/// The name of `value` (its first row), or "?" for a value the table lacks.
template<typename E>
const char* nameOf(std::span<const EnumName<E>> table, E value)
{
    for (const auto& row : table)
        if (row.value == value) return row.name.data();
    return "?";
}

/// The value named `name`. @throw lic::InputError `WHAT "name" is unknown; expected a, b or c`.
template<typename E>
E valueOf(std::span<const EnumName<E>> table, const std::string& name, std::string_view what)
{
    for (const auto& row : table)
        if (row.name == name) return row.value;
    throw InputError(std::string(what) + " \"" + name + "\" is unknown; expected " + listNames(table));
}

} // namespace lic

// Names of enum values: one table per enum gives both directions, and the error for an unknown
// name lists the table, so a new value is added in one place.
#pragma once

#include "lic/util/Error.h"

#include <span>
#include <string>
#include <string_view>

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

/// "a, b or c" of the table's listed names (aliases left out), each followed by " (note)" if any.
template<typename E>
std::string listNames(std::span<const EnumName<E>> table)
{
    std::string out;
    std::size_t listed = 0, total = 0;
    for (std::size_t i = 0; i < table.size(); ++i) {
        bool alias = false;
        for (std::size_t j = 0; j < i; ++j) alias = alias || table[j].value == table[i].value;
        if (!alias) ++total;
    }
    for (std::size_t i = 0; i < table.size(); ++i) {
        bool alias = false;
        for (std::size_t j = 0; j < i; ++j) alias = alias || table[j].value == table[i].value;
        if (alias) continue;
        if (listed > 0) out += listed + 1 == total ? " or " : ", ";
        out += table[i].name;
        if (!table[i].note.empty()) out += " (" + std::string(table[i].note) + ")";
        ++listed;
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

#include "vdbexport/io/Numbers.h"

#include <lic/util/Error.h>

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace vdbexport {

std::vector<double> parseNumberList(const std::string& flag, const std::string& text, const char* expected,
                                    std::size_t count)
{
    std::vector<double> v;
    std::stringstream in(text);
    std::string part;
    while (std::getline(in, part, ',')) {
        try {
            std::size_t used = 0;
            v.push_back(std::stod(part, &used));
            if (used != part.size() || !std::isfinite(v.back())) throw std::invalid_argument(part);
        } catch (const std::exception&) {
            throw lic::InputError(flag + " \"" + text + "\": \"" + part + "\" is not a finite number; expected " +
                                  expected);
        }
    }
    if (v.empty()) throw lic::InputError(flag + " \"" + text + "\" is empty; expected " + expected);
    if (count > 0 && v.size() != count)
        throw lic::InputError(flag + " \"" + text + "\" has " + std::to_string(v.size()) + " numbers; expected " +
                              expected);
    return v;
}

std::array<int, 2> parseFrameRange(const std::string& flag, const std::string& text)
{
    const auto v = parseNumberList(flag, text, "FIRST,LAST", 2);
    if (v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]) || v[0] < 0 || v[1] < v[0] || v[1] - v[0] >= 100000)
        throw lic::InputError(flag + " " + text + ": expected FIRST,LAST whole frame numbers, 0 <= FIRST <= LAST, at most 100000 frames");
    return {int(v[0]), int(v[1])};
}

} // namespace vdbexport

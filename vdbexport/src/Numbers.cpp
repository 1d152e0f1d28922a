#include "vdbexport/Numbers.h"

#include <lic/Error.h>

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

} // namespace vdbexport

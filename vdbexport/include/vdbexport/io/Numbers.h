// Comma-separated numbers given as a command-line value ("1024,768", "0.3,2", "X0,Y0,Z0,X1,Y1,Z1").
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace vdbexport {

/// Parse `text`, the value of `flag`, as comma-separated finite numbers. With `count` > 0 exactly
/// that many are required.
/// @throw lic::InputError naming the flag, the value, the offending part and `expected`.
std::vector<double> parseNumberList(const std::string& flag, const std::string& text, const char* expected,
                                    std::size_t count = 0);

/// Parse `text`, the value of `flag`, as FIRST,LAST whole frame numbers, 0 <= FIRST <= LAST, at
/// most 100000 frames.
/// @throw lic::InputError naming the flag and the value.
std::array<int, 2> parseFrameRange(const std::string& flag, const std::string& text);

} // namespace vdbexport

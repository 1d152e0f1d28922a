// Colormaps by name or from a user's LUT file.
#pragma once

#include "lic/composite/Colormap.h"

#include <string>

namespace vdbexport {

/// A colormap by name (lic::Colormap::named), or from a `value,r,g,b` .csv file (sRGB values).
/// @throw lic::InputError for an unknown name or an unreadable or malformed file.
lic::Colormap loadColormap(const std::string& spec);

} // namespace vdbexport

#include "vdbexport/io/ColormapFile.h"

#include "lic/util/Error.h"

#include <filesystem>
#include <fstream>
#include <sstream>

namespace vdbexport {

lic::Colormap loadColormap(const std::string& spec)
{
    if (std::filesystem::path(spec).extension() != ".csv") return lic::Colormap::named(spec);
    std::ifstream in(spec);
    if (!in) throw lic::InputError("colormap LUT file \"" + spec + "\" cannot be read");
    std::stringstream text;
    text << in.rdbuf();
    return lic::Colormap::fromCsv(text.str(), spec);
}

} // namespace vdbexport

#include "vdbexport/io/OutputNames.h"

#include <filesystem>

namespace vdbexport {

namespace fs = std::filesystem;

std::string numberedPath(const std::string& vdbPath, int frame)
{
    fs::path p(vdbPath);
    const fs::path stem = p.extension() == ".vdb" ? p.stem() : p.filename();
    std::string digits = std::to_string(frame);
    if (digits.size() < 4) digits.insert(0, 4 - digits.size(), '0');
    return (p.parent_path() / (stem.string() + "_" + digits + ".vdb")).string();
}

std::string framePath(const std::string& vdbPath, int frame, int frames)
{
    return frames <= 1 ? vdbPath : numberedPath(vdbPath, frame);
}

std::string manifestPath(const std::string& vdbPath)
{
    // Not OUT.json: that is what a recipe for OUT.vdb is naturally called (`--recipe jet.json
    // --out jet.vdb`), and the bake would refuse to overwrite it. The add-on still reads OUT.json
    // beside bakes made before the rename (blender_addon/licvdb/manifest.py).
    fs::path p(vdbPath);
    if (p.extension() == ".vdb") p.replace_extension();
    p += manifestSuffix;
    return p.string();
}

} // namespace vdbexport

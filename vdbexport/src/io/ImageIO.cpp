// The image functions of ImageIO.h. Those that need OpenImageIO or OpenColorIO run in the image
// module (licvdb-image.so, ImageModule.cpp), loaded on first use: see ImageModuleApi.h.
#include "vdbexport/io/ImageIO.h"

#include "vdbexport/io/Program.h"
#include "vdbexport/io/AtomicWrite.h"

#include "ImageModuleApi.h"
#include "Quote.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>

namespace fs = std::filesystem;

namespace vdbexport {

namespace {

using detail::q;

std::string lowerExtension(const std::string& path)
{
    std::string e = fs::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

using image_module::formatFor;

/// Check the image path (known extension, writable directory) and return the temporary name to
/// write first; see detail::prepareAtomicWrite.
std::string prepare(const std::string& path)
{
    if (path.empty()) throw lic::InputError("cannot write an image with an empty path; expected a file name");
    if (formatFor(path).empty())
        throw lic::InputError("cannot write " + q(path) + ": unknown image extension " +
                              q(fs::path(path).extension().string()) + "; expected .png, .exr, .jpg, .tif or .gif");
    return detail::prepareAtomicWrite(path);
}

void commit(const std::string& tmp, const std::string& path) { detail::commitAtomicWrite(tmp, path); }

/// The module's table, loaded once (never unloaded). @throw lic::Error naming where it looked.
const image_module::Api& imageModule()
{
    static const module::Spec spec{"image module", image_module::kModule, kImageModuleEnv,
                                   LICVDB_IMAGE_MODULE_BUILD, LICVDB_IMAGE_MODULE_INSTALLED,
                                   "OpenImageIO, OpenColorIO"};
    try {
        return *static_cast<const image_module::Api*>(module::load(spec));
    } catch (const lic::Error& e) {
        throw lic::Error(std::string("cannot read or write images: ") + e.what());
    }
}

using module::check;

/// Runs `write(tmp)` on the temporary name of `path`, then commits; removes it on failure.
template <typename F>
void atomically(const std::string& path, F&& write)
{
    const std::string tmp = prepare(path); // the path's own errors first
    try {
        check(write(imageModule(), tmp));
    } catch (...) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw;
    }
    commit(tmp, path);
}

} // namespace

std::string findOcioConfig(const std::string& explicitPath)
{
    std::error_code ec;
    if (!explicitPath.empty()) {
        if (!fs::is_regular_file(explicitPath, ec))
            throw lic::InputError("OCIO config " + q(explicitPath) + " does not exist; expected a config.ocio file");
        return explicitPath;
    }
    if (const char* env = std::getenv(kOcioConfigEnv); env && *env) {
        if (!fs::is_regular_file(env, ec))
            throw lic::InputError(std::string("$") + kOcioConfigEnv + " = " + q(env) +
                                  " does not exist; expected a config.ocio file");
        return env;
    }
    std::vector<fs::path> candidates;
    const fs::path exe = program::path();
    if (!exe.empty()) {
        const fs::path dir = exe.parent_path();
        candidates.push_back(dir / ".." / "share" / "licvdb" / "ocio" / "config.ocio");
        candidates.push_back(dir / ".." / ".." / "share" / "licvdb" / "ocio" / "config.ocio"); // libexec/licvdb/
        candidates.push_back(dir / ".." / ".." / "share" / "ocio" / "config.ocio");
    }
#ifdef LICVDB_OCIO_CONFIG_DEFAULT
    candidates.emplace_back(LICVDB_OCIO_CONFIG_DEFAULT);
#endif
    for (const auto& c : candidates)
        if (fs::is_regular_file(c, ec)) return fs::weakly_canonical(c, ec).string();
    throw lic::InputError(std::string("cannot find licvdb's OCIO config (share/ocio/config.ocio); set $") +
                          kOcioConfigEnv + " or pass --ocio-config");
}

std::string viewFromFlag(const std::string& flag)
{
    if (flag == "standard" || flag == "Standard") return "Standard";
    if (flag == "filmic" || flag == "Filmic") return "Filmic";
    if (flag == "raw" || flag == "Raw") return "Raw";
    throw lic::InputError("unknown view transform \"" + flag + "\"; expected standard or filmic (or raw)");
}

std::vector<float> toDisplay(const lic::Image& image, const DisplayTransform& t)
{
    std::vector<float> rgb;
    check(imageModule().toDisplay(image, t, rgb));
    return rgb;
}

bool isSceneLinearPath(const std::string& path)
{
    const std::string f = formatFor(path);
    if (f.empty())
        throw lic::InputError("unknown image extension " + q(fs::path(path).extension().string()) + " in " +
                              q(path) + "; expected .png, .exr, .jpg, .tif or .gif");
    return f == "openexr";
}

void writeImageAtomic(const std::string& path, const lic::Image& image, const DisplayTransform& transform,
                      const std::map<std::string, std::string>& metadata)
{
    atomically(path, [&](const image_module::Api& api, const std::string& tmp) {
        return api.writeImage(path, tmp, image, transform, metadata);
    });
}

void writeGifAtomic(const std::string& path, const std::vector<lic::Image>& frames, const DisplayTransform& transform,
                    double fps)
{
    if (frames.empty()) throw lic::InputError("cannot write " + q(path) + ": no frames");
    if (lowerExtension(path) != ".gif")
        throw lic::InputError("cannot write an animation to " + q(path) + "; expected a .gif path");
    for (const auto& f : frames)
        if (f.width != frames[0].width || f.height != frames[0].height)
            throw lic::InputError("cannot write " + q(path) + ": frames differ in size");
    atomically(path, [&](const image_module::Api& api, const std::string& tmp) {
        return api.writeGif(path, tmp, frames, transform, fps);
    });
}

std::string canonicalColorSpace(const std::string& oiioName)
{
    std::string lower(oiioName);
    for (char& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
    for (const char* name : {"linear", "lin_rec709", "lin_srgb", "lin_rec709_scene"})
        if (lower == name) return "lin_rec709_scene";
    for (const char* name : {"srgb", "srgb_rec709_scene"})
        if (lower == name) return "srgb_rec709_scene";
    return oiioName;
}

lic::Image readImage(const std::string& path, std::string* colorSpace)
{
    lic::Image image;
    std::string stored;
    check(imageModule().readImage(path, image, stored));
    if (colorSpace) *colorSpace = canonicalColorSpace(stored);
    return image;
}

} // namespace vdbexport

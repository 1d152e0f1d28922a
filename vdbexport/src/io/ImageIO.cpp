#include "vdbexport/io/ImageIO.h"
#include "vdbexport/io/VdbIO.h"

#include <lic/util/Error.h>

#include <OpenColorIO/OpenColorIO.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>

#include <fcntl.h>
#include <unistd.h>

namespace OCIO = OCIO_NAMESPACE;
namespace fs = std::filesystem;

namespace vdbexport {

namespace {

std::string quote(const std::string& s) { return "'" + s + "'"; }

std::string lowerExtension(const std::string& path)
{
    std::string e = fs::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

/// OIIO format name for an output extension; empty if unsupported.
std::string formatFor(const std::string& path)
{
    const std::string e = lowerExtension(path);
    if (e == ".exr") return "openexr";
    if (e == ".png") return "png";
    if (e == ".jpg" || e == ".jpeg") return "jpeg";
    if (e == ".tif" || e == ".tiff") return "tiff";
    if (e == ".gif") return "gif";
    return "";
}

/// Check the image path (known extension, writable directory) and return the temporary name to
/// write first; see detail::prepareAtomicWrite.
std::string prepare(const std::string& path)
{
    if (path.empty()) throw lic::InputError("cannot write an image with an empty path; expected a file name");
    if (formatFor(path).empty())
        throw lic::InputError("cannot write " + quote(path) + ": unknown image extension " +
                              quote(fs::path(path).extension().string()) + "; expected .png, .exr, .jpg, .tif or .gif");
    return detail::prepareAtomicWrite(path);
}

void commit(const std::string& tmp, const std::string& path) { detail::commitAtomicWrite(tmp, path); }

/// Display-encoded float RGB → 8-bit, rounding to nearest.
std::vector<unsigned char> toBytes(const std::vector<float>& rgb)
{
    std::vector<unsigned char> out(rgb.size());
    for (std::size_t i = 0; i < rgb.size(); ++i) {
        const float v = std::clamp(rgb[i], 0.0f, 1.0f);
        out[i] = static_cast<unsigned char>(std::lround(v * 255.0f));
    }
    return out;
}

/// Write `subimages` (each a packed buffer with `spec`) to `tmp` with OIIO; throws lic::Error.
void writeWithOiio(const std::string& path, const std::string& tmp, const std::vector<OIIO::ImageSpec>& specs,
                   const std::vector<const void*>& pixels)
{
    auto out = OIIO::ImageOutput::create(formatFor(path));
    if (!out) throw lic::Error("cannot write " + quote(path) + ": OpenImageIO has no writer for it (" + OIIO::geterror() + ")");
    const bool multi = specs.size() > 1;
    if (multi && !out->supports("multiimage"))
        throw lic::Error("cannot write " + quote(path) + ": the format does not hold several images");
    bool ok = multi ? out->open(tmp, int(specs.size()), specs.data()) : out->open(tmp, specs[0]);
    for (std::size_t i = 0; ok && i < specs.size(); ++i) {
        if (i > 0) ok = out->open(tmp, specs[i], OIIO::ImageOutput::AppendSubimage);
        if (ok) ok = out->write_image(specs[i].format, pixels[i]);
    }
    const bool closed = out->close();
    if (!ok || !closed) {
        const std::string msg = out->geterror();
        std::error_code ec;
        fs::remove(tmp, ec);
        throw lic::Error("cannot write " + quote(path) + ": " + (msg.empty() ? std::string("write failed") : msg));
    }
}

} // namespace

std::string findOcioConfig(const std::string& explicitPath)
{
    std::error_code ec;
    if (!explicitPath.empty()) {
        if (!fs::is_regular_file(explicitPath, ec))
            throw lic::InputError("OCIO config " + quote(explicitPath) + " does not exist; expected a config.ocio file");
        return explicitPath;
    }
    if (const char* env = std::getenv(kOcioConfigEnv); env && *env) {
        if (!fs::is_regular_file(env, ec))
            throw lic::InputError(std::string("$") + kOcioConfigEnv + " = " + quote(env) +
                                  " does not exist; expected a config.ocio file");
        return env;
    }
    std::vector<fs::path> candidates;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        const fs::path dir = exe.parent_path();
        candidates.push_back(dir / ".." / "share" / "licvdb" / "ocio" / "config.ocio");
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
    std::vector<float> rgb(std::size_t(image.width) * std::size_t(image.height) * 3);
    for (std::size_t i = 0, n = rgb.size() / 3; i < n; ++i)
        for (int c = 0; c < 3; ++c) rgb[i * 3 + std::size_t(c)] = image.rgba[i * 4 + std::size_t(c)];
    OCIO::ConstCPUProcessorRcPtr cpu;
    try {
        OCIO::ConstConfigRcPtr config = OCIO::Config::CreateFromFile(t.config.c_str());
        OCIO::ConstProcessorRcPtr proc =
            config->getProcessor(OCIO::ROLE_SCENE_LINEAR, t.display.c_str(), t.view.c_str(), OCIO::TRANSFORM_DIR_FORWARD);
        cpu = proc->getDefaultCPUProcessor();
    } catch (const OCIO::Exception& e) {
        throw lic::InputError("OCIO display transform (config " + quote(t.config) + ", display " + quote(t.display) +
                              ", view " + quote(t.view) + "): " + e.what());
    }
    if (!rgb.empty()) {
        OCIO::PackedImageDesc desc(rgb.data(), image.width, image.height, 3);
        cpu->apply(desc);
    }
    for (float& v : rgb) v = std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f;
    return rgb;
}

bool isSceneLinearPath(const std::string& path)
{
    const std::string f = formatFor(path);
    if (f.empty())
        throw lic::InputError("unknown image extension " + quote(fs::path(path).extension().string()) + " in " +
                              quote(path) + "; expected .png, .exr, .jpg, .tif or .gif");
    return f == "openexr";
}

void writeImageAtomic(const std::string& path, const lic::Image& image, const DisplayTransform& transform,
                      const std::map<std::string, std::string>& metadata)
{
    const std::string tmp = prepare(path);
    OIIO::ImageSpec spec;
    std::vector<float> linear;
    std::vector<unsigned char> bytes;
    const void* data = nullptr;
    if (isSceneLinearPath(path)) {
        spec = OIIO::ImageSpec(image.width, image.height, 4, OIIO::TypeDesc::FLOAT);
        spec.channelnames = {"R", "G", "B", "A"};
        spec.alpha_channel = 3;
        spec.attribute("oiio:ColorSpace", "Linear");
        // Rec.709 / sRGB primaries and D65 white: red, green, blue, white (x, y).
        const float chroma[8] = {0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f};
        spec.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), chroma);
        spec.attribute("compression", "zip");
        data = image.rgba.data();
    } else {
        spec = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
        spec.attribute("oiio:ColorSpace", "sRGB");
        bytes = toBytes(toDisplay(image, transform));
        data = bytes.data();
    }
    for (const auto& [k, v] : metadata) spec.attribute(k, v);
    writeWithOiio(path, tmp, {spec}, {data});
    commit(tmp, path);
}

void writeGifAtomic(const std::string& path, const std::vector<lic::Image>& frames, const DisplayTransform& transform,
                    double fps)
{
    if (frames.empty()) throw lic::InputError("cannot write " + quote(path) + ": no frames");
    if (lowerExtension(path) != ".gif")
        throw lic::InputError("cannot write an animation to " + quote(path) + "; expected a .gif path");
    const std::string tmp = prepare(path);
    std::vector<std::vector<unsigned char>> bytes;
    std::vector<OIIO::ImageSpec> specs;
    std::vector<const void*> data;
    const int num = std::max(1, int(std::lround(fps * 100.0)));
    for (const auto& f : frames) {
        if (f.width != frames[0].width || f.height != frames[0].height)
            throw lic::InputError("cannot write " + quote(path) + ": frames differ in size");
        bytes.push_back(toBytes(toDisplay(f, transform)));
        OIIO::ImageSpec spec(f.width, f.height, 3, OIIO::TypeDesc::UINT8);
        const int rate[2] = {num, 100};
        spec.attribute("FramesPerSecond", OIIO::TypeRational, rate);
        spec.attribute("oiio:Movie", 1);
        spec.attribute("oiio:LoopCount", 0);
        specs.push_back(spec);
    }
    for (const auto& b : bytes) data.push_back(b.data());
    writeWithOiio(path, tmp, specs, data);
    commit(tmp, path);
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
    auto in = OIIO::ImageInput::open(path);
    if (!in) throw lic::InputError("cannot read image " + quote(path) + ": " + OIIO::geterror());
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<float> buf(std::size_t(spec.width) * std::size_t(spec.height) * std::size_t(spec.nchannels));
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, buf.data()))
        throw lic::InputError("cannot read image " + quote(path) + ": " + in->geterror());
    if (colorSpace) *colorSpace = canonicalColorSpace(spec.get_string_attribute("oiio:ColorSpace"));
    lic::Image img(spec.width, spec.height);
    const std::size_t nc = std::size_t(spec.nchannels);
    for (std::size_t i = 0, n = std::size_t(spec.width) * std::size_t(spec.height); i < n; ++i) {
        for (std::size_t c = 0; c < 3; ++c) img.rgba[i * 4 + c] = buf[i * nc + std::min(c, nc - 1)];
        img.rgba[i * 4 + 3] = nc >= 4 ? buf[i * nc + 3] : 1.0f;
    }
    in->close();
    return img;
}

} // namespace vdbexport

// licvdb-image.so: image files and display transforms through OpenImageIO and OpenColorIO,
// loaded by licvdb on first use (ImageModuleApi.h says why). The public functions and the
// atomic write around these entries are in ImageIO.cpp.
#include "ImageModuleApi.h"

#include "Quote.h"

#include <lic/util/Error.h>

#include <OpenColorIO/OpenColorIO.h>
#include <OpenImageIO/imageio.h>

#include <cmath>
#include <system_error>

namespace OCIO = OCIO_NAMESPACE;
namespace fs = std::filesystem;

namespace vdbexport::image_module {

namespace {

using detail::q;

/// Runs `body`, reporting its exceptions as a Status (none crosses into licvdb).
template <typename F>
Status guarded(F&& body)
{
    return module::guarded(std::forward<F>(body), "the image module");
}

std::vector<float> display(const lic::Image& image, const DisplayTransform& t)
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
        throw lic::InputError("OCIO display transform (config " + q(t.config) + ", display " + q(t.display) +
                              ", view " + q(t.view) + "): " + e.what());
    }
    if (!rgb.empty()) {
        OCIO::PackedImageDesc desc(rgb.data(), image.width, image.height, 3);
        cpu->apply(desc);
    }
    for (float& v : rgb) v = std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f;
    return rgb;
}

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
    if (!out) throw lic::Error("cannot write " + q(path) + ": OpenImageIO has no writer for it (" + OIIO::geterror() + ")");
    const bool multi = specs.size() > 1;
    if (multi && !out->supports("multiimage"))
        throw lic::Error("cannot write " + q(path) + ": the format does not hold several images");
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
        throw lic::Error("cannot write " + q(path) + ": " + (msg.empty() ? std::string("write failed") : msg));
    }
}

Status toDisplayEntry(const lic::Image& image, const DisplayTransform& transform, std::vector<float>& rgb)
{
    return guarded([&] { rgb = display(image, transform); });
}

Status writeImageEntry(const std::string& path, const std::string& tmp, const lic::Image& image,
                       const DisplayTransform& transform, const std::map<std::string, std::string>& metadata)
{
    return guarded([&] {
        OIIO::ImageSpec spec;
        std::vector<unsigned char> bytes;
        const void* data = nullptr;
        if (formatFor(path) == "openexr") {
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
            bytes = toBytes(display(image, transform));
            data = bytes.data();
        }
        for (const auto& [k, v] : metadata) spec.attribute(k, v);
        writeWithOiio(path, tmp, {spec}, {data});
    });
}

Status writeGifEntry(const std::string& path, const std::string& tmp, const std::vector<lic::Image>& frames,
                     const DisplayTransform& transform, double fps)
{
    return guarded([&] {
        std::vector<std::vector<unsigned char>> bytes;
        std::vector<OIIO::ImageSpec> specs;
        std::vector<const void*> data;
        const int num = std::max(1, int(std::lround(fps * 100.0)));
        for (const auto& f : frames) {
            bytes.push_back(toBytes(display(f, transform)));
            OIIO::ImageSpec spec(f.width, f.height, 3, OIIO::TypeDesc::UINT8);
            const int rate[2] = {num, 100};
            spec.attribute("FramesPerSecond", OIIO::TypeRational, rate);
            spec.attribute("oiio:Movie", 1);
            spec.attribute("oiio:LoopCount", 0);
            specs.push_back(spec);
        }
        for (const auto& b : bytes) data.push_back(b.data());
        writeWithOiio(path, tmp, specs, data);
    });
}

Status readImageEntry(const std::string& path, lic::Image& image, std::string& colorSpace)
{
    return guarded([&] {
        auto in = OIIO::ImageInput::open(path);
        if (!in) throw lic::InputError("cannot read image " + q(path) + ": " + OIIO::geterror());
        const OIIO::ImageSpec& spec = in->spec();
        std::vector<float> buf(std::size_t(spec.width) * std::size_t(spec.height) * std::size_t(spec.nchannels));
        if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, buf.data()))
            throw lic::InputError("cannot read image " + q(path) + ": " + in->geterror());
        colorSpace = spec.get_string_attribute("oiio:ColorSpace");
        lic::Image img(spec.width, spec.height);
        const std::size_t nc = std::size_t(spec.nchannels);
        for (std::size_t i = 0, n = std::size_t(spec.width) * std::size_t(spec.height); i < n; ++i) {
            for (std::size_t c = 0; c < 3; ++c) img.rgba[i * 4 + c] = buf[i * nc + std::min(c, nc - 1)];
            img.rgba[i * 4 + 3] = nc >= 4 ? buf[i * nc + 3] : 1.0f;
        }
        in->close();
        image = std::move(img);
    });
}

const Api kApi{kModule.version, toDisplayEntry, writeImageEntry, writeGifEntry, readImageEntry};

} // namespace

} // namespace vdbexport::image_module

extern "C" __attribute__((visibility("default"))) const vdbexport::image_module::Api* licvdb_image_module()
{
    return &vdbexport::image_module::kApi;
}

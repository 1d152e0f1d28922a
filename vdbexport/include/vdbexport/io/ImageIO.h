// Writing rendered images: scene-linear OpenEXR, and display-referred PNG/JPEG/TIFF/GIF through
// an OpenColorIO display/view transform (our own small OCIO 2.1 config, share/ocio/config.ocio).
// Every file is written to a temporary name and renamed, so a failure leaves no partial file.
// OpenImageIO and OpenColorIO live in licvdb's image module (licvdb-image.so), loaded on the first
// call that needs them (toDisplay, writeImageAtomic, writeGifAtomic, readImage): found through
// $LICVDB_IMAGE_MODULE, beside the program, in its ../libexec/licvdb/, in licvdb's build tree or
// where licvdb was installed; missing, those calls throw lic::Error saying where it looked.
#pragma once

#include <lic/render/Image.h>

#include <map>
#include <string>
#include <vector>

namespace vdbexport {

/// Environment variable naming the image module's file (licvdb-image.so) to load, instead of
/// looking for it (a program linking lic::vdbexport from a prefix licvdb was not configured for).
inline constexpr const char* kImageModuleEnv = "LICVDB_IMAGE_MODULE";

/// Environment variable that overrides the OCIO config licvdb ships.
inline constexpr const char* kOcioConfigEnv = "LICVDB_OCIO_CONFIG";

/// @brief The OCIO config to use: `explicitPath` if given, else $LICVDB_OCIO_CONFIG, else the
///        shipped config next to the executable (`<exe>/../share/licvdb/ocio/config.ocio`, then
///        `<exe>/../../share/ocio/config.ocio`), else the source tree's `share/ocio/config.ocio`.
/// @throw lic::InputError if an explicit or environment path does not exist, or none is found.
std::string findOcioConfig(const std::string& explicitPath = "");

/// An OCIO display/view transform from the config's scene_linear role.
struct DisplayTransform
{
    std::string config;            ///< path of an OCIO config (see findOcioConfig)
    std::string display = "sRGB";
    std::string view = "Standard"; ///< "Standard" (clip + sRGB curve) or "Filmic" (tone curve)
};

/// `standard` → "Standard", `filmic` → "Filmic", `raw` → "Raw".
/// @throw lic::InputError for other names.
std::string viewFromFlag(const std::string& flag);

/// @brief Apply the display transform to a scene-linear RGBA image (alpha ignored: black
///        background). Returns display-encoded RGB floats in [0, 1], 3 per pixel, rows top down.
/// @throw lic::InputError if the config cannot be read or lacks the display or view.
std::vector<float> toDisplay(const lic::Image& image, const DisplayTransform& transform);

/// True for extensions written scene-linear (.exr); false for display-referred ones (.png,
/// .jpg, .jpeg, .tif, .tiff, .gif). @throw lic::InputError for any other extension.
bool isSceneLinearPath(const std::string& path);

/// @brief Write one image. `.exr`: RGBA 32-bit float, scene-linear Rec.709 (tagged with
///        `oiio:ColorSpace` = "Linear" and Rec.709 `chromaticities`; read back as
///        "lin_rec709_scene", see canonicalColorSpace), premultiplied alpha.
///        Others: 8-bit RGB after `transform` (tagged `oiio:ColorSpace` = "sRGB").
/// @param metadata string attributes stored in the file (e.g. `Software`, `ImageDescription`)
/// @throw lic::InputError for an unsupported extension or an unusable output directory;
///        lic::Error if writing fails. No partial file is left behind.
void writeImageAtomic(const std::string& path, const lic::Image& image, const DisplayTransform& transform,
                      const std::map<std::string, std::string>& metadata = {});

/// @brief Write an animated GIF (looping forever) of `frames` at `fps` frames per second, each
///        through `transform`. @throw as writeImageAtomic; lic::InputError if frames differ in size.
void writeGifAtomic(const std::string& path, const std::vector<lic::Image>& frames, const DisplayTransform& transform,
                    double fps = 12.0);

/// @brief Read an image back as float RGBA (for tests and tools): channels beyond 4 dropped,
///        missing alpha = 1. `colorSpace` (if given) receives OpenImageIO's `oiio:ColorSpace`
///        through canonicalColorSpace. @throw lic::InputError if it cannot be read.
lic::Image readImage(const std::string& path, std::string* colorSpace = nullptr);

/// @brief One name per colour space whatever OpenImageIO reads it as: scene-linear Rec.709 is
///        "Linear" in OIIO 2.4 and "lin_rec709_scene" in OIIO 3.x (aliases "linear", "lin_rec709",
///        "lin_srgb"), sRGB is "sRGB" in 2.4 and "srgb_rec709_scene" in 3.x. Returns
///        "lin_rec709_scene" or "srgb_rec709_scene" (OIIO 3's and OCIO's built-in names) for
///        those, any other name unchanged.
std::string canonicalColorSpace(const std::string& oiioName);

} // namespace vdbexport

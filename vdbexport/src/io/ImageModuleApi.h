// The image module's interface: what licvdb-image.so (ImageModule.cpp: OpenImageIO, OpenColorIO)
// gives the loader in ImageIO.cpp. OpenImageIO links some 260 shared libraries (codecs, OpenCV,
// FFmpeg, GDAL...) whose relocation cost every licvdb start ~0.3 s of CPU; only image commands
// (render, the gallery's pictures) need them, so they are loaded on first use (Module.h).
#pragma once

#include "Module.h"
#include "vdbexport/io/ImageIO.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace vdbexport::image_module {

inline constexpr module::Identity kModule{"licvdb-image.so", "licvdb_image_module", /*version=*/1};

using module::Status;

/// The table (kModule.version is bumped whenever it changes).
struct Api
{
    int version;
    /// See vdbexport::toDisplay.
    Status (*toDisplay)(const lic::Image& image, const DisplayTransform& transform, std::vector<float>& rgb);
    /// Write one image to `tmp` (`path` is for messages and the format): see writeImageAtomic.
    Status (*writeImage)(const std::string& path, const std::string& tmp, const lic::Image& image,
                         const DisplayTransform& transform, const std::map<std::string, std::string>& metadata);
    /// Write an animated GIF to `tmp`: see writeGifAtomic.
    Status (*writeGif)(const std::string& path, const std::string& tmp, const std::vector<lic::Image>& frames,
                       const DisplayTransform& transform, double fps);
    /// Read an image as float RGBA; `colorSpace` receives OpenImageIO's oiio:ColorSpace as stored.
    Status (*readImage)(const std::string& path, lic::Image& image, std::string& colorSpace);
};

/// OpenImageIO's format name for an output path's extension; empty if unsupported.
inline std::string formatFor(const std::string& path)
{
    std::string e = std::filesystem::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (e == ".exr") return "openexr";
    if (e == ".png") return "png";
    if (e == ".jpg" || e == ".jpeg") return "jpeg";
    if (e == ".tif" || e == ".tiff") return "tiff";
    if (e == ".gif") return "gif";
    return "";
}

} // namespace vdbexport::image_module

extern "C" const vdbexport::image_module::Api* licvdb_image_module();

// The image the reference raycaster renders, and the two ways to put a stereo pair's eyes into
// one image.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace lic {

/// A scene-linear RGBA float image, rows top to bottom, premultiplied alpha (black background:
/// alpha = 1 − transmittance of the ray).
struct Image
{
    int width = 0;
    int height = 0;
    std::vector<float> rgba; ///< 4 × width × height

    Image() = default;
    Image(int w, int h) : width(w), height(h), rgba(std::size_t(w) * std::size_t(h) * 4, 0.0f) {}
    float* pixel(int x, int y) { return rgba.data() + (std::size_t(y) * std::size_t(width) + std::size_t(x)) * 4; }
    const float* pixel(int x, int y) const
    {
        return rgba.data() + (std::size_t(y) * std::size_t(width) + std::size_t(x)) * 4;
    }
};

enum class StereoMode { None, SideBySide, Anaglyph };
/// @throw lic::InputError for names other than none, sbs, anaglyph.
StereoMode stereoFromString(const std::string&);
const char* toString(StereoMode);

/// Left eye on the left, right eye on the right (parallel viewing): 2W × H.
Image sideBySide(const Image& left, const Image& right);
/// Red–cyan anaglyph: red from the left eye, green and blue from the right. W × H.
Image anaglyph(const Image& left, const Image& right);

} // namespace lic

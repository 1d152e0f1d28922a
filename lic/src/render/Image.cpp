#include "lic/render/Image.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"

#include <algorithm>

namespace lic {

namespace {
constexpr EnumName<StereoMode> kStereoNames[] = {{StereoMode::None, "none"},
                                                 {StereoMode::SideBySide, "sbs", "side by side"},
                                                 {StereoMode::Anaglyph, "anaglyph"},
                                                 {StereoMode::SideBySide, "side-by-side"},
                                                 {StereoMode::None, ""}};
} // namespace

StereoMode stereoFromString(const std::string& s) { return valueOf<StereoMode>(kStereoNames, s, "stereo mode"); }

const char* toString(StereoMode m) { return nameOf<StereoMode>(kStereoNames, m); }

Image sideBySide(const Image& l, const Image& r)
{
    if (l.width != r.width || l.height != r.height) throw Error("stereo eyes differ in size");
    Image out(l.width * 2, l.height);
    for (int y = 0; y < l.height; ++y) {
        std::copy_n(l.pixel(0, y), 4 * l.width, out.pixel(0, y));
        std::copy_n(r.pixel(0, y), 4 * r.width, out.pixel(l.width, y));
    }
    return out;
}

Image anaglyph(const Image& l, const Image& r)
{
    if (l.width != r.width || l.height != r.height) throw Error("stereo eyes differ in size");
    Image out(l.width, l.height);
    for (std::size_t i = 0; i < out.rgba.size(); i += 4) {
        out.rgba[i + 0] = l.rgba[i + 0];
        out.rgba[i + 1] = r.rgba[i + 1];
        out.rgba[i + 2] = r.rgba[i + 2];
        out.rgba[i + 3] = std::max(l.rgba[i + 3], r.rgba[i + 3]);
    }
    return out;
}

} // namespace lic

// Colormaps: named maps defined in sRGB, user LUTs, and conversion to scene-linear Rec.709.
#pragma once

#include <openvdb/openvdb.h>

#include <string>
#include <utility>
#include <vector>

namespace lic {

/// sRGB transfer function decode (IEC 61966-2-1): encoded [0,1] → linear [0,1].
double srgbToLinear(double v);
/// Relative luminance Y of a scene-linear Rec.709 colour.
inline double luminance(const openvdb::Vec3d& linear)
{
    return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2];
}

/// A colormap: sRGB control points at increasing positions in [0, 1], interpolated linearly in
/// sRGB (as matplotlib and Blender's colour ramp in sRGB do), converted to scene-linear Rec.709
/// for the `color` grid.
class Colormap
{
public:
    using Point = std::pair<double, openvdb::Vec3d>; // (position in [0,1], sRGB in [0,1])

    /// Built-in maps: heated-object, red-yellow, grey-purple, viridis, magma, inferno, cividis,
    /// coolwarm.
    static const std::vector<std::string>& names();
    /// @throw lic::InputError for an unknown name (the message lists names() and says a CSV LUT
    ///        file may be given instead).
    static Colormap named(const std::string& name);
    /// A user LUT: CSV lines `value,r,g,b` (r, g, b in [0, 1], or 0–255 if any exceeds 1); values
    /// strictly increasing, remapped to [0, 1]; `#` comments and blank lines ignored.
    /// @throw lic::InputError naming `source` and the line for malformed input.
    static Colormap fromCsv(const std::string& text, const std::string& source);

    const std::string& name() const { return mName; }
    const std::vector<Point>& points() const { return mPoints; }
    /// sRGB colour at t (clamped to [0, 1]).
    openvdb::Vec3d srgb(double t) const;
    /// Scene-linear Rec.709 colour at t.
    openvdb::Vec3d linear(double t) const;

private:
    Colormap(std::string name, std::vector<Point> points);
    std::string mName;
    std::vector<Point> mPoints;
};

} // namespace lic

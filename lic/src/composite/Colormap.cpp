#include "lic/composite/Colormap.h"

#include "lic/util/Error.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

namespace lic {

double srgbToLinear(double v)
{
    return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

namespace {

using Rgb = openvdb::Vec3d;

/// Evenly spaced sRGB control points. The perceptual maps (viridis, magma, inferno, cividis,
/// coolwarm) are matplotlib's, sampled at 33 points (CC0 / public domain data).
const std::map<std::string, std::vector<Rgb>>& tables()
{
    static const std::map<std::string, std::vector<Rgb>> t{
        // Levkowitz & Herman's heated-object scale: black → red → orange → yellow → white,
        // luminance increasing throughout (seed figure 13, vorticity magnitude).
        {"heated-object", {{0.0, 0.0, 0.0}, {0.45, 0.02, 0.0}, {0.8, 0.15, 0.0}, {0.95, 0.45, 0.0},
                           {1.0, 0.75, 0.1}, {1.0, 0.93, 0.55}, {1.0, 1.0, 1.0}}},
        // Red → yellow (seed figure 14, temperature).
        {"red-yellow", {{0.65, 0.0, 0.0}, {0.9, 0.25, 0.0}, {1.0, 0.55, 0.0}, {1.0, 0.8, 0.1}, {1.0, 0.97, 0.3}}},
        // Saturation wash, grey → purple (seed figure 14, streamwise vorticity).
        {"grey-purple", {{0.55, 0.55, 0.55}, {0.56, 0.45, 0.64}, {0.57, 0.32, 0.74}, {0.56, 0.16, 0.82}}},
    {"viridis", {{0.2670, 0.0049, 0.3294}, {0.2770, 0.0503, 0.3757}, {0.2823, 0.0950, 0.4173}, {0.2829, 0.1359, 0.4534}, {0.2788, 0.1755, 0.4834}, {0.2706, 0.2141, 0.5071}, {0.2590, 0.2515, 0.5247}, {0.2450, 0.2877, 0.5373}, {0.2297, 0.3224, 0.5457}, {0.2143, 0.3556, 0.5512}, {0.1994, 0.3876, 0.5546}, {0.1856, 0.4186, 0.5568}, {0.1727, 0.4488, 0.5579}, {0.1607, 0.4785, 0.5581}, {0.1490, 0.5081, 0.5573}, {0.1378, 0.5375, 0.5549}, {0.1276, 0.5669, 0.5506}, {0.1211, 0.5927, 0.5446}, {0.1201, 0.6222, 0.5349}, {0.1301, 0.6514, 0.5216}, {0.1539, 0.6802, 0.5042}, {0.1911, 0.7084, 0.4823}, {0.2394, 0.7356, 0.4557}, {0.2965, 0.7616, 0.4242}, {0.3607, 0.7860, 0.3878}, {0.4310, 0.8085, 0.3465}, {0.5063, 0.8288, 0.3004}, {0.5857, 0.8467, 0.2499}, {0.6681, 0.8620, 0.1963}, {0.7519, 0.8750, 0.1432}, {0.8353, 0.8860, 0.1026}, {0.9162, 0.8961, 0.1007}, {0.9932, 0.9062, 0.1439}}},
    {"magma", {{0.0015, 0.0005, 0.0139}, {0.0137, 0.0118, 0.0687}, {0.0396, 0.0311, 0.1335}, {0.0743, 0.0520, 0.2027}, {0.1131, 0.0655, 0.2768}, {0.1590, 0.0684, 0.3527}, {0.2117, 0.0620, 0.4186}, {0.2654, 0.0602, 0.4618}, {0.3167, 0.0717, 0.4854}, {0.3660, 0.0903, 0.4980}, {0.4147, 0.1104, 0.5047}, {0.4635, 0.1299, 0.5077}, {0.5128, 0.1482, 0.5076}, {0.5629, 0.1654, 0.5047}, {0.6136, 0.1818, 0.4985}, {0.6649, 0.1981, 0.4888}, {0.7164, 0.2150, 0.4753}, {0.7611, 0.2312, 0.4602}, {0.8109, 0.2529, 0.4393}, {0.8578, 0.2799, 0.4155}, {0.8996, 0.3146, 0.3910}, {0.9336, 0.3588, 0.3705}, {0.9585, 0.4113, 0.3600}, {0.9751, 0.4689, 0.3631}, {0.9857, 0.5281, 0.3794}, {0.9922, 0.5875, 0.4063}, {0.9958, 0.6463, 0.4414}, {0.9973, 0.7046, 0.4826}, {0.9970, 0.7624, 0.5288}, {0.9954, 0.8199, 0.5791}, {0.9928, 0.8772, 0.6331}, {0.9898, 0.9343, 0.6902}, {0.9871, 0.9914, 0.7495}}},
    {"inferno", {{0.0015, 0.0005, 0.0139}, {0.0140, 0.0112, 0.0719}, {0.0423, 0.0281, 0.1411}, {0.0820, 0.0433, 0.2153}, {0.1293, 0.0473, 0.2908}, {0.1834, 0.0403, 0.3550}, {0.2383, 0.0366, 0.3964}, {0.2908, 0.0456, 0.4186}, {0.3415, 0.0623, 0.4294}, {0.3915, 0.0809, 0.4331}, {0.4412, 0.0993, 0.4316}, {0.4910, 0.1172, 0.4256}, {0.5409, 0.1347, 0.4151}, {0.5907, 0.1526, 0.4003}, {0.6401, 0.1714, 0.3811}, {0.6887, 0.1922, 0.3576}, {0.7357, 0.2159, 0.3302}, {0.7751, 0.2397, 0.3035}, {0.8173, 0.2710, 0.2704}, {0.8560, 0.3070, 0.2351}, {0.8903, 0.3480, 0.1983}, {0.9199, 0.3934, 0.1601}, {0.9443, 0.4428, 0.1204}, {0.9634, 0.4955, 0.0791}, {0.9771, 0.5508, 0.0391}, {0.9853, 0.6084, 0.0242}, {0.9879, 0.6677, 0.0583}, {0.9849, 0.7284, 0.1208}, {0.9761, 0.7900, 0.1960}, {0.9625, 0.8515, 0.2855}, {0.9487, 0.9105, 0.3953}, {0.9517, 0.9606, 0.5242}, {0.9884, 0.9984, 0.6449}}},
    {"cividis", {{0.0000, 0.1351, 0.3048}, {0.0000, 0.1579, 0.3575}, {0.0000, 0.1788, 0.4148}, {0.0179, 0.1985, 0.4412}, {0.1034, 0.2204, 0.4358}, {0.1543, 0.2425, 0.4301}, {0.1951, 0.2644, 0.4259}, {0.2309, 0.2861, 0.4235}, {0.2637, 0.3078, 0.4228}, {0.2947, 0.3295, 0.4237}, {0.3242, 0.3513, 0.4263}, {0.3529, 0.3732, 0.4302}, {0.3808, 0.3952, 0.4357}, {0.4082, 0.4174, 0.4426}, {0.4352, 0.4398, 0.4511}, {0.4616, 0.4624, 0.4620}, {0.4887, 0.4853, 0.4710}, {0.5142, 0.5055, 0.4726}, {0.5441, 0.5289, 0.4719}, {0.5744, 0.5527, 0.4692}, {0.6052, 0.5768, 0.4644}, {0.6364, 0.6013, 0.4578}, {0.6680, 0.6262, 0.4493}, {0.7000, 0.6515, 0.4386}, {0.7324, 0.6774, 0.4257}, {0.7652, 0.7037, 0.4106}, {0.7985, 0.7306, 0.3926}, {0.8322, 0.7580, 0.3715}, {0.8664, 0.7860, 0.3466}, {0.9012, 0.8146, 0.3170}, {0.9367, 0.8438, 0.2809}, {0.9731, 0.8736, 0.2347}, {0.9957, 0.9093, 0.2178}}},
    {"coolwarm", {{0.2298, 0.2987, 0.7537}, {0.2662, 0.3531, 0.8015}, {0.3039, 0.4065, 0.8450}, {0.3428, 0.4588, 0.8837}, {0.3830, 0.5094, 0.9174}, {0.4244, 0.5581, 0.9456}, {0.4667, 0.6046, 0.9682}, {0.5096, 0.6483, 0.9848}, {0.5530, 0.6889, 0.9954}, {0.5963, 0.7261, 0.9998}, {0.6392, 0.7596, 0.9982}, {0.6813, 0.7890, 0.9904}, {0.7222, 0.8140, 0.9766}, {0.7615, 0.8343, 0.9569}, {0.7987, 0.8498, 0.9317}, {0.8335, 0.8602, 0.9011}, {0.8654, 0.8654, 0.8654}, {0.8978, 0.8489, 0.8209}, {0.9241, 0.8274, 0.7745}, {0.9445, 0.8009, 0.7267}, {0.9589, 0.7698, 0.6780}, {0.9673, 0.7341, 0.6288}, {0.9700, 0.6943, 0.5794}, {0.9668, 0.6504, 0.5303}, {0.9580, 0.6028, 0.4818}, {0.9437, 0.5518, 0.4342}, {0.9239, 0.4973, 0.3880}, {0.8990, 0.4396, 0.3432}, {0.8692, 0.3783, 0.3003}, {0.8346, 0.3129, 0.2593}, {0.7956, 0.2413, 0.2205}, {0.7525, 0.1572, 0.1841}, {0.7057, 0.0156, 0.1502}}},
    };
    return t;
}

} // namespace

Colormap::Colormap(std::string name, std::vector<Point> points)
    : mName(std::move(name))
    , mPoints(std::move(points))
{
}

const std::vector<std::string>& Colormap::names()
{
    static const std::vector<std::string> n{"heated-object", "red-yellow", "grey-purple", "viridis",
                                            "magma",         "inferno",    "cividis",     "coolwarm"};
    return n;
}

Colormap Colormap::named(const std::string& name)
{
    const auto it = tables().find(name);
    if (it == tables().end()) {
        std::string list;
        for (const auto& n : names()) list += (list.empty() ? "" : ", ") + n;
        throw InputError("colormap \"" + name + "\" is unknown; expected one of " + list +
                         ", or a .csv LUT file (value,r,g,b per line)");
    }
    std::vector<Point> pts;
    const std::size_t n = it->second.size();
    for (std::size_t i = 0; i < n; ++i) pts.emplace_back(double(i) / double(n - 1), it->second[i]);
    return Colormap(name, std::move(pts));
}

Colormap Colormap::fromCsv(const std::string& text, const std::string& source)
{
    std::vector<std::pair<double, Rgb>> rows;
    std::istringstream in(text);
    std::string line;
    int lineNo = 0;
    while (std::getline(in, line)) {
        ++lineNo;
        const auto hash = line.find('#');
        if (hash != std::string::npos) line.resize(hash);
        if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream fields(line);
        double v, r, g, b;
        std::string extra;
        if (!(fields >> v >> r >> g >> b) || (fields >> extra)) {
            throw InputError(source + ":" + std::to_string(lineNo) +
                             ": expected 4 numbers value,r,g,b; got \"" + line + "\"");
        }
        if (!std::isfinite(v) || !std::isfinite(r) || !std::isfinite(g) || !std::isfinite(b) || r < 0 ||
            g < 0 || b < 0) {
            throw InputError(source + ":" + std::to_string(lineNo) + ": values must be finite and r,g,b >= 0");
        }
        if (!rows.empty() && !(v > rows.back().first)) {
            throw InputError(source + ":" + std::to_string(lineNo) + ": value " + std::to_string(v) +
                             " must be greater than the previous line's");
        }
        rows.emplace_back(v, Rgb(r, g, b));
    }
    if (rows.size() < 2) throw InputError(source + ": a colormap LUT needs at least 2 lines (value,r,g,b)");
    double maxComponent = 0;
    for (const auto& [v, c] : rows) maxComponent = std::max({maxComponent, c[0], c[1], c[2]});
    const double scale = maxComponent > 1.0 ? 1.0 / 255.0 : 1.0;
    if (maxComponent > 255.0) throw InputError(source + ": r,g,b must be in [0, 1] or [0, 255]");
    const double lo = rows.front().first, hi = rows.back().first;
    std::vector<Point> pts;
    for (const auto& [v, c] : rows) pts.emplace_back((v - lo) / (hi - lo), c * scale);
    return Colormap(source, std::move(pts));
}

openvdb::Vec3d Colormap::srgb(double t) const
{
    if (!(t > 0)) return mPoints.front().second; // also NaN
    if (t >= 1) return mPoints.back().second;
    const auto it = std::upper_bound(mPoints.begin(), mPoints.end(), t,
                                     [](double x, const Point& p) { return x < p.first; });
    const Point& b = *it;
    const Point& a = *(it - 1);
    const double f = (t - a.first) / (b.first - a.first);
    return a.second + (b.second - a.second) * f;
}

openvdb::Vec3d Colormap::linear(double t) const
{
    const Rgb c = srgb(t);
    return Rgb(srgbToLinear(c[0]), srgbToLinear(c[1]), srgbToLinear(c[2]));
}

} // namespace lic

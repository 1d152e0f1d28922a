// Seeds files: world-space spot centres as .npy (N, 3) or text `x y z` lines.
#include "vdbexport/io/SeedPoints.h"

#include "io/DenseCommon.h"

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace vdbexport {

using namespace detail;

namespace {

/// Refuse an empty set or more than kMaxSeedPoints (before allocating).
void checkCount(std::uint64_t n, const std::string& source)
{
    if (n == 0) inputError(source, "holds no seed points; expected at least one x y z point");
    if (n > kMaxSeedPoints)
        inputError(source, "holds " + std::to_string(n) + " seed points, more than the limit of " +
                               std::to_string(kMaxSeedPoints) + "; thin the points out (or use input.distribution)");
}

/// Element `index` of a float32/float64 array, byte-swapped if `swap`, as double.
double loadDouble(const unsigned char* p, Elem e, bool swap, std::size_t index)
{
    const std::size_t n = elemSize(e);
    unsigned char b[8];
    std::memcpy(b, p + index * n, n);
    if (swap)
        for (std::size_t i = 0; i < n / 2; ++i) std::swap(b[i], b[n - 1 - i]);
    if (e == Elem::F32) {
        float v;
        std::memcpy(&v, b, 4);
        return v;
    }
    double v;
    std::memcpy(&v, b, 8);
    return v;
}

/// The next number of `line` from `pos` (skipping spaces, tabs, commas); false if there is none.
bool nextNumber(std::string_view line, std::size_t& pos, double& value)
{
    while (pos < line.size() && (line[pos] == ' ' || line[pos] == '\t' || line[pos] == ',' || line[pos] == '\r')) ++pos;
    if (pos >= line.size()) return false;
    std::size_t begin = pos;
    if (line[begin] == '+') ++begin; // from_chars takes no '+'
    const auto res = std::from_chars(line.data() + begin, line.data() + line.size(), value);
    if (res.ec == std::errc::invalid_argument) return false;
    if (res.ec == std::errc::result_out_of_range) value = HUGE_VAL; // reported as not finite
    pos = std::size_t(res.ptr - line.data());
    return true;
}

/// The three numbers of text line `number` (1-based); throws naming the line otherwise.
openvdb::Vec3d parseLine(std::string_view line, std::size_t number, const std::string& source)
{
    openvdb::Vec3d p;
    std::size_t pos = 0;
    int count = 0;
    double v;
    while (count < 4 && nextNumber(line, pos, v)) {
        if (count < 3) p[count] = v;
        ++count;
    }
    while (pos < line.size() && (line[pos] == ' ' || line[pos] == '\t' || line[pos] == ',' || line[pos] == '\r')) ++pos;
    if (count != 3 || pos < line.size()) {
        std::string shown(line.substr(0, 60));
        while (!shown.empty() && shown.back() == '\r') shown.pop_back();
        inputError(source, "line " + std::to_string(number) + " is not three numbers x y z: " + q(shown));
    }
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
        inputError(source, "line " + std::to_string(number) + " has a NaN or infinite coordinate; seed points must be finite");
    return p;
}

} // namespace

std::vector<openvdb::Vec3d> parseSeedNpy(std::string_view bytes, const std::string& source)
{
    const NpyArray a = parseNpyArray(bytes, source);
    if (a.shape.size() != 2 || a.shape[1] != 3) {
        std::string s = "(";
        for (std::size_t i = 0; i < a.shape.size(); ++i) s += (i ? ", " : "") + std::to_string(a.shape[i]);
        inputError(source, "has shape " + s + (a.shape.size() == 1 ? ",)" : ")") + "; expected (N, 3): one x, y, z row per seed point");
    }
    if (a.elem != Elem::F32 && a.elem != Elem::F64)
        inputError(source, "has dtype '" + a.descr + "'; expected float32 or float64 seed points");
    const std::uint64_t n = std::uint64_t(a.shape[0]);
    checkCount(n, source);
    if (n * 3 * elemSize(a.elem) != a.available)
        inputError(source, "the header declares " + std::to_string(n) + " points (" + std::to_string(n * 3 * elemSize(a.elem)) +
                               " bytes) but the file holds " + std::to_string(a.available) + " bytes of data");
    const bool swap = a.bigEndian == hostIsLittle();
    std::vector<openvdb::Vec3d> points(n);
    for (std::uint64_t i = 0; i < n; ++i) {
        for (std::uint64_t c = 0; c < 3; ++c) {
            const std::uint64_t index = a.fortran ? c * n + i : i * 3 + c;
            points[i][int(c)] = loadDouble(a.data, a.elem, swap, std::size_t(index));
        }
        if (!std::isfinite(points[i][0]) || !std::isfinite(points[i][1]) || !std::isfinite(points[i][2]))
            inputError(source, "row " + std::to_string(i) + " (counting from 0) has a NaN or infinite coordinate; seed points must be finite");
    }
    return points;
}

std::vector<openvdb::Vec3d> parseSeedText(std::string_view text, const std::string& source)
{
    std::vector<openvdb::Vec3d> points;
    std::size_t begin = 0, number = 0;
    while (begin < text.size()) {
        std::size_t end = text.find('\n', begin);
        if (end == std::string_view::npos) end = text.size();
        std::string_view line = text.substr(begin, end - begin);
        begin = end + 1;
        ++number;
        if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
        if (line.find_first_not_of(" \t\r") == std::string_view::npos) continue;
        if (points.size() == kMaxSeedPoints) checkCount(kMaxSeedPoints + 1, source);
        points.push_back(parseLine(line, number, source));
    }
    checkCount(points.size(), source);
    return points;
}

std::vector<openvdb::Vec3d> readSeedPoints(const std::string& path)
{
    namespace fs = std::filesystem;
    std::error_code ec;
    const std::string source = "seeds file " + q(path);
    if (!fs::exists(path, ec)) throw lic::InputError(source + " not found; expected a .npy (N, 3) or a text file of x y z lines");
    if (fs::is_directory(path, ec)) throw lic::InputError(source + " is a directory; expected a .npy or text file of points");
    std::ifstream in(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    if (!in.good() && !in.eof()) throw lic::InputError("cannot read " + source);
    std::string ext = fs::path(path).extension().string();
    for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    const std::string data = bytes.str();
    return ext == ".npy" ? parseSeedNpy(data, path) : parseSeedText(data, path);
}

} // namespace vdbexport

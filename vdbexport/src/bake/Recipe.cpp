// Recipe JSON reading, writing and validation. One table per struct (Schema<T>) lists its
// JSON keys and members; the same table drives the key check, parsing and serialisation,
// so the three cannot drift apart.
#include "vdbexport/bake/Recipe.h"
#include "vdbexport/io/InputFormats.h"

#include "lic/engine/Engine.h"
#include "lic/engine/Settings.h"
#include "lic/engine/Streamline.h"
#include "lic/texture/Noise.h"
#include "lic/texture/Spots.h"
#include "lic/util/Error.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <tuple>

namespace vdbexport {
namespace {

using nlohmann::json;

// ---- formatting -------------------------------------------------------------------------

/// Shortest text that reads back as the same double (20, 0.5, 0.001, 1e+20).
std::string fmt(double v)
{
    if (std::isnan(v)) return "nan";
    if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
    char buf[32];
    auto res = std::to_chars(buf, buf + sizeof(buf), v);
    return std::string(buf, res.ptr);
}

std::string quote(const std::string& s) { return json(s).dump(); }

std::string joinQuoted(const std::vector<std::string>& values)
{
    std::string out;
    for (const auto& v : values) out += (out.empty() ? "" : ", ") + quote(v);
    return out;
}

/// "string \"20\"", "number 2.5", "boolean true", "null", "array [1,2]", "an object".
std::string describe(const json& j)
{
    auto clip = [](std::string s) { return s.size() > 40 ? s.substr(0, 37) + "..." : s; };
    switch (j.type()) {
    case json::value_t::null: return "null";
    case json::value_t::object: return "an object";
    case json::value_t::array: return "array " + clip(j.dump());
    case json::value_t::string: return "string " + clip(j.dump());
    case json::value_t::boolean: return "boolean " + j.dump();
    default: return "number " + j.dump();
    }
}

// ---- where a value sits, for error messages ---------------------------------------------

struct Where
{
    const std::string& source;
    std::string path; // "lic.length", "input.radii[1]"; "" at the top level

    Where operator/(const std::string& key) const
    {
        return {source, path.empty() ? key : path + "." + key};
    }
    Where at(std::size_t i) const { return {source, path + "[" + std::to_string(i) + "]"}; }

    [[noreturn]] void fail(const std::string& what) const
    {
        throw lic::InputError(source + ": " + (path.empty() ? "" : path + ": ") + what);
    }
    [[noreturn]] void expected(const std::string& type, const json& got) const
    {
        fail("expected " + type + ", got " + describe(got));
    }
};

// ---- the tables -------------------------------------------------------------------------

template <class S, class M>
struct Field
{
    const char* key;
    M S::*member;
};
template <class S, class M>
constexpr Field<S, M> field(const char* key, M S::*member) { return {key, member}; }

template <class T> struct Schema;

template <> struct Schema<FieldSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("path", &FieldSpec::path), field("grid", &FieldSpec::grid),
            field("format", &FieldSpec::format), field("voxel_size", &FieldSpec::voxelSize),
            field("origin", &FieldSpec::origin), field("shape", &FieldSpec::shape),
            field("dtype", &FieldSpec::dtype), field("resample", &FieldSpec::resample),
            field("crop", &FieldSpec::crop), field("mask", &FieldSpec::mask),
            field("nan_policy", &FieldSpec::nanPolicy), field("frames", &FieldSpec::frames),
            field("fps", &FieldSpec::fps), field("time", &FieldSpec::time),
            field("solution", &FieldSpec::solution));
    }
};
template <> struct Schema<OutputSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("path", &OutputSpec::path), field("upsample", &OutputSpec::upsample),
            field("contrast", &OutputSpec::contrast), field("half", &OutputSpec::half));
    }
};
template <> struct Schema<SurfaceSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("scalar", &SurfaceSpec::scalar), field("threshold", &SurfaceSpec::threshold));
    }
};
template <> struct Schema<InputSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("type", &InputSpec::type), field("distribution", &InputSpec::distribution),
            field("spacing", &InputSpec::spacing), field("jitter", &InputSpec::jitter),
            field("radii", &InputSpec::radii), field("halo_scale", &InputSpec::haloScale),
            field("seed", &InputSpec::seed), field("noise_filter", &InputSpec::noiseFilter),
            field("surface", &InputSpec::surface), field("seeds", &InputSpec::seeds));
    }
};
template <> struct Schema<RoiSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("scalar", &RoiSpec::scalar), field("range", &RoiSpec::range),
            field("mode", &RoiSpec::mode));
    }
};
template <> struct Schema<LicSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("engine", &LicSpec::engine), field("kernel", &LicSpec::kernel),
            field("length", &LicSpec::length), field("step", &LicSpec::step), field("decay", &LicSpec::decay),
            field("integrator", &LicSpec::integrator), field("tolerance", &LicSpec::tolerance),
            field("min_hits", &LicSpec::minHits), field("brick", &LicSpec::brick));
    }
};
template <> struct Schema<WidthSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("scalar", &WidthSpec::scalar), field("range", &WidthSpec::range),
            field("invert", &WidthSpec::invert));
    }
};
template <> struct Schema<ColorSpec>
{
    static auto fields()
    {
        return std::make_tuple(field("scalar", &ColorSpec::scalar), field("colormap", &ColorSpec::colormap),
            field("range", &ColorSpec::range));
    }
};
template <> struct Schema<AnimationSpec>
{
    static auto fields() { return std::make_tuple(field("frames", &AnimationSpec::frames)); }
};
template <> struct Schema<Recipe>
{
    static auto fields()
    {
        return std::make_tuple(field("field", &Recipe::field), field("output", &Recipe::output),
            field("input", &Recipe::input), field("roi", &Recipe::roi), field("lic", &Recipe::lic),
            field("width", &Recipe::width), field("color", &Recipe::color),
            field("animation", &Recipe::animation), field("threads", &Recipe::threads));
    }
};

template <class T>
concept Described = requires { Schema<T>::fields(); };

/// Keys a struct reads from a table of its own rather than from its Schema: none by default.
template <class T> struct TableKeys
{
    static std::vector<std::string> keys() { return {}; }
    static bool get(const T&, const std::string&) { return false; }
    static void set(T&, const std::string&, bool) {}
};

/// `output.write_*`: one boolean per recipe key of the output-grid table.
template <> struct TableKeys<OutputSpec>
{
    static std::vector<std::string> keys()
    {
        std::vector<std::string> keys;
        for (const lic::OutputGridRow& row : lic::outputGrids())
            if (!row.recipeKey.empty() && std::find(keys.begin(), keys.end(), row.recipeKey) == keys.end())
                keys.emplace_back(row.recipeKey);
        return keys;
    }
    static bool get(const OutputSpec& o, const std::string& key) { return o.grids.hasKey(key); }
    static void set(OutputSpec& o, const std::string& key, bool on) { o.grids.setKey(key, on); }
};

template <Described T>
std::vector<std::string> keysOf()
{
    std::vector<std::string> keys;
    std::apply([&](auto... f) { (keys.emplace_back(f.key), ...); }, Schema<T>::fields());
    for (std::string& key : TableKeys<T>::keys()) keys.push_back(std::move(key));
    return keys;
}

// Declared ahead so the struct readers and writers find each other (a member may itself be
// a described struct or an optional one).
template <Described T> void read(const json& j, const Where& w, T& out);
template <Described T> void read(const json& j, const Where& w, std::optional<T>& out);
template <Described T> json write(const T& v);
template <Described T> json write(const std::optional<T>& v);

// ---- reading ----------------------------------------------------------------------------

void read(const json& j, const Where& w, std::string& out)
{
    if (!j.is_string()) w.expected("a string", j);
    out = j.get<std::string>();
}

void read(const json& j, const Where& w, bool& out)
{
    if (!j.is_boolean()) w.expected("a boolean (true or false)", j);
    out = j.get<bool>();
}

void read(const json& j, const Where& w, double& out)
{
    if (!j.is_number()) w.expected("a number", j);
    out = j.get<double>();
}

/// An integer in [lo, hi]; a float with an integral value (2.0) is accepted.
template <class I>
I readInteger(const json& j, const Where& w, const char* type)
{
    constexpr double lo = double(std::numeric_limits<I>::min());
    constexpr double hi = double(std::numeric_limits<I>::max());
    if (j.is_number_unsigned()) {
        const auto v = j.get<std::uint64_t>();
        if (v <= std::uint64_t(std::numeric_limits<I>::max())) return I(v);
    } else if (j.is_number_integer()) {
        const auto v = j.get<std::int64_t>();
        if (v >= std::int64_t(std::numeric_limits<I>::min()) &&
            (v < 0 || std::uint64_t(v) <= std::uint64_t(std::numeric_limits<I>::max()))) {
            return I(v);
        }
    } else if (j.is_number_float()) {
        const double v = j.get<double>();
        if (v == std::floor(v) && v >= lo && v < hi) return I(v);
    }
    w.expected(type, j);
}

void read(const json& j, const Where& w, int& out) { out = readInteger<int>(j, w, "an integer"); }

void read(const json& j, const Where& w, std::uint64_t& out)
{
    out = readInteger<std::uint64_t>(j, w, "a non-negative integer");
}

void read(const json& j, const Where& w, std::vector<double>& out)
{
    if (!j.is_array()) w.expected("an array of numbers", j);
    out.assign(j.size(), 0.0);
    for (std::size_t i = 0; i < j.size(); ++i) read(j[i], w.at(i), out[i]);
}

void read(const json& j, const Where& w, std::array<double, 2>& out)
{
    if (!j.is_array() || j.size() != 2) w.expected("[lo, hi] (an array of two numbers)", j);
    for (std::size_t i = 0; i < 2; ++i) read(j[i], w.at(i), out[i]);
}

/// null or "auto" = automatic (nullopt), or [lo, hi].
void read(const json& j, const Where& w, std::optional<std::array<double, 2>>& out)
{
    if (j.is_null() || (j.is_string() && j.get<std::string>() == "auto")) {
        out.reset();
        return;
    }
    if (!j.is_array()) w.expected("\"auto\" or [lo, hi]", j);
    std::array<double, 2> range{};
    read(j, w, range);
    out = range;
}

/// null = absent, else a number.
void read(const json& j, const Where& w, std::optional<double>& out)
{
    if (j.is_null()) {
        out.reset();
        return;
    }
    if (!j.is_number()) w.expected("a number or null", j);
    out = j.get<double>();
}

void read(const json& j, const Where& w, std::optional<std::array<int, 2>>& out)
{
    if (j.is_null()) {
        out.reset();
        return;
    }
    if (!j.is_array() || j.size() != 2) w.expected("[first, last] (two frame numbers) or null", j);
    std::array<int, 2> v{};
    for (std::size_t i = 0; i < 2; ++i) read(j[i], w.at(i), v[i]);
    out = v;
}

void read(const json& j, const Where& w, std::array<double, 3>& out)
{
    if (!j.is_array() || j.size() != 3) w.expected("[x, y, z] (an array of three numbers)", j);
    for (std::size_t i = 0; i < 3; ++i) read(j[i], w.at(i), out[i]);
}

/// null = absent, else [x, y, z].
void read(const json& j, const Where& w, std::optional<std::array<double, 3>>& out)
{
    if (j.is_null()) {
        out.reset();
        return;
    }
    std::array<double, 3> v{};
    read(j, w, v);
    out = v;
}

/// null = absent, else [[x0, y0, z0], [x1, y1, z1]].
void read(const json& j, const Where& w, std::optional<std::array<std::array<double, 3>, 2>>& out)
{
    if (j.is_null()) {
        out.reset();
        return;
    }
    if (!j.is_array() || j.size() != 2) w.expected("[[x0, y0, z0], [x1, y1, z1]] or null", j);
    std::array<std::array<double, 3>, 2> v{};
    for (std::size_t i = 0; i < 2; ++i) read(j[i], w.at(i), v[i]);
    out = v;
}

/// Every key of object `j` must be one of `valid`.
void checkKeys(const json& j, const Where& w, const std::vector<std::string>& valid)
{
    for (const auto& item : j.items()) {
        if (std::find(valid.begin(), valid.end(), item.key()) != valid.end()) continue;
        const std::string hint = suggestKey(item.key(), valid);
        throw lic::InputError(w.source + ": unknown key " + quote((w / item.key()).path) +
            (hint.empty() ? "; valid keys here: " + joinQuoted(valid) : "; did you mean " + quote(hint) + "?"));
    }
}

template <Described T>
void read(const json& j, const Where& w, T& out)
{
    if (!j.is_object()) w.expected("an object", j);
    checkKeys(j, w, keysOf<T>());
    std::apply(
        [&](auto... f) {
            (
                [&] {
                    const auto it = j.find(f.key);
                    if (it != j.end()) read(*it, w / f.key, out.*(f.member));
                }(),
                ...);
        },
        Schema<T>::fields());
    for (const std::string& key : TableKeys<T>::keys()) {
        if (const auto it = j.find(key); it != j.end()) {
            bool on = false;
            read(*it, w / key, on);
            TableKeys<T>::set(out, key, on);
        }
    }
}

/// null = absent; an object is merged onto the section's defaults.
template <Described T>
void read(const json& j, const Where& w, std::optional<T>& out)
{
    if (j.is_null()) {
        out.reset();
        return;
    }
    if (!j.is_object()) w.expected("an object or null", j);
    T value{};
    read(j, w, value);
    out = std::move(value);
}

// ---- writing ----------------------------------------------------------------------------

template <class T>
json write(const T& v) { return json(v); }

// Arrays element by element: json(std::array) trips GCC 12's -Wnull-dereference at -O3.
json write(const std::vector<double>& v)
{
    json j = json::array();
    for (double x : v) j.push_back(x);
    return j;
}

json write(const std::array<double, 2>& v) { return write(std::vector<double>(v.begin(), v.end())); }

json write(const std::optional<std::array<double, 2>>& v) { return v ? write(*v) : json("auto"); }

json write(const std::optional<double>& v) { return v ? json(*v) : json(nullptr); }

json write(const std::array<double, 3>& v) { return write(std::vector<double>(v.begin(), v.end())); }

json write(const std::optional<std::array<double, 3>>& v) { return v ? write(*v) : json(nullptr); }

json write(const std::optional<std::array<int, 2>>& v) { return v ? json{(*v)[0], (*v)[1]} : json(nullptr); }

json write(const std::optional<std::array<std::array<double, 3>, 2>>& v)
{
    if (!v) return json(nullptr);
    json j = json::array();
    j.push_back(write((*v)[0]));
    j.push_back(write((*v)[1]));
    return j;
}

template <Described T>
json write(const T& v)
{
    json j = json::object();
    std::apply([&](auto... f) { ((j[f.key] = write(v.*(f.member))), ...); }, Schema<T>::fields());
    for (const std::string& key : TableKeys<T>::keys()) j[key] = TableKeys<T>::get(v, key);
    return j;
}

template <Described T>
json write(const std::optional<T>& v) { return v ? write(*v) : json(nullptr); }

// ---- validation -------------------------------------------------------------------------

[[noreturn]] void violation(const std::string& path, const std::string& rule, const std::string& got)
{
    throw lic::InputError(path + ": must be " + rule + " (got " + got + ")");
}

// Written as !(ok) so NaN always fails.
void checkPositive(const std::string& path, double v)
{
    if (!(v > 0) || std::isinf(v)) violation(path, "> 0", fmt(v));
}

void checkRange(const std::string& path, double v, double lo, double hi, bool loOpen, bool hiOpen)
{
    const bool ok = (loOpen ? v > lo : v >= lo) && (hiOpen ? v < hi : v <= hi);
    if (!ok) violation(path, "in " + std::string(loOpen ? "(" : "[") + fmt(lo) + ", " + fmt(hi) + (hiOpen ? ")" : "]"), fmt(v));
}

void checkInt(const std::string& path, int v, int lo, int hi)
{
    if (v < lo || v > hi) violation(path, "in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", std::to_string(v));
}

void checkChoice(const std::string& path, const std::string& v)
{
    const auto& allowed = allowedValues(path);
    if (std::find(allowed.begin(), allowed.end(), v) != allowed.end()) return;
    const std::string hint = suggestKey(v, allowed);
    throw lic::InputError(path + ": must be one of " + joinQuoted(allowed) + " (got " + quote(v) + ")" +
        (hint.empty() ? "" : "; did you mean " + quote(hint) + "?"));
}

void checkScalar(const std::string& path, const std::string& v)
{
    if (v.empty()) {
        violation(path, "a scalar name (speed, vorticity, streamwise-vorticity, helicity, q-criterion, "
                        "lambda2, or a float grid of the field file)", "\"\"");
    }
}

void checkInterval(const std::string& path, const std::array<double, 2>& r)
{
    if (!std::isfinite(r[0]) || !std::isfinite(r[1]) || !(r[0] < r[1])) {
        std::string got = "[";
        got += fmt(r[0]);
        got += ", ";
        got += fmt(r[1]);
        got += "]";
        violation(path, "[lo, hi] with finite lo < hi", got);
    }
}

} // namespace

// ---- public -----------------------------------------------------------------------------

nlohmann::json Recipe::toJson() const { return write(*this); }

Recipe Recipe::fromJson(const nlohmann::json& j, const std::string& source)
{
    Recipe r;
    if (!j.is_object()) throw lic::InputError(source + ": expected a JSON object at the top level, got " + describe(j));
    read(j, Where{source, ""}, r);
    return r;
}

void Recipe::validate() const
{
    checkChoice("field.format", field.format);
    checkChoice("field.dtype", field.dtype);
    checkChoice("field.mask", field.mask);
    checkChoice("field.nan_policy", field.nanPolicy);
    if (field.voxelSize) checkPositive("field.voxel_size", *field.voxelSize);
    if (field.resample) checkPositive("field.resample", *field.resample);
    if (field.time && !std::isfinite(*field.time)) violation("field.time", "a finite time", fmt(*field.time));
    if (field.origin) {
        for (std::size_t a = 0; a < 3; ++a) {
            const double v = (*field.origin)[a];
            if (!std::isfinite(v)) violation("field.origin[" + std::to_string(a) + "]", "finite", fmt(v));
        }
    }
    if (field.shape) {
        for (std::size_t a = 0; a < 3; ++a) {
            const double v = (*field.shape)[a];
            if (!(v >= 1) || v != std::floor(v) || v > 1e9)
                violation("field.shape[" + std::to_string(a) + "]", "an integer in [1, 1e9]", fmt(v));
        }
    }
    if (field.crop) {
        const auto& c = *field.crop;
        for (std::size_t a = 0; a < 3; ++a) {
            if (!std::isfinite(c[0][a]) || !std::isfinite(c[1][a]) || !(c[0][a] < c[1][a])) {
                violation("field.crop", "[[x0, y0, z0], [x1, y1, z1]] with finite x0 < x1, y0 < y1, z0 < z1",
                          "[" + fmt(c[0][a]) + ", " + fmt(c[1][a]) + "] on axis " + "xyz"[a]);
            }
        }
    }

    checkInt("output.upsample", output.upsample, 1, 16);
    checkChoice("output.contrast", output.contrast);

    checkChoice("input.type", input.type);
    checkChoice("input.distribution", input.distribution);
    checkChoice("input.noise_filter", input.noiseFilter);
    checkPositive("input.spacing", input.spacing);
    checkRange("input.jitter", input.jitter, 0, 1, false, false);
    if (input.radii.empty()) violation("input.radii", "a non-empty array of radii", "[]");
    for (std::size_t i = 0; i < input.radii.size(); ++i) {
        const std::string path = "input.radii[" + std::to_string(i) + "]";
        checkPositive(path, input.radii[i]);
        if (i > 0 && !(input.radii[i] > input.radii[i - 1])) {
            violation(path, "> input.radii[" + std::to_string(i - 1) + "] = " + fmt(input.radii[i - 1]) +
                " (radii must be strictly increasing)", fmt(input.radii[i]));
        }
    }
    if (!(input.haloScale >= 1) || std::isinf(input.haloScale)) violation("input.halo_scale", ">= 1", fmt(input.haloScale));
    if (input.surface) {
        checkScalar("input.surface.scalar", input.surface->scalar);
        if (!std::isfinite(input.surface->threshold)) violation("input.surface.threshold", "finite", fmt(input.surface->threshold));
        if (!input.seeds.empty())
            violation("input.seeds", "\"\" with input.surface (spots come from the seeds file or the surface, not both)",
                      quote(input.seeds));
    }

    if (roi) {
        checkScalar("roi.scalar", roi->scalar);
        checkInterval("roi.range", roi->range);
        checkChoice("roi.mode", roi->mode);
    }

    checkChoice("lic.engine", lic.engine);
    checkChoice("lic.kernel", lic.kernel);
    checkRange("lic.length", lic.length, 0, 10000, true, false);
    checkPositive("lic.step", lic.step);
    if (!(lic.step <= lic.length)) violation("lic.step", "<= lic.length = " + fmt(lic.length), fmt(lic.step));
    checkRange("lic.decay", lic.decay, 0, 1, true, true);
    checkChoice("lic.integrator", lic.integrator);
    checkPositive("lic.tolerance", lic.tolerance);
    checkInt("lic.min_hits", lic.minHits, 1, 64);
    if (lic.brick != 0 && (lic.brick < 8 || lic.brick > 512 || lic.brick % 8 != 0))
        violation("lic.brick", "0 (automatic) or a multiple of 8 in 8..512", std::to_string(lic.brick));

    if (width) {
        checkScalar("width.scalar", width->scalar);
        if (width->range) checkInterval("width.range", *width->range);
    }
    if (color) {
        checkScalar("color.scalar", color->scalar);
        if (color->colormap.empty()) violation("color.colormap", "a colormap name", "\"\"");
        if (color->range) checkInterval("color.range", *color->range);
    }

    checkInt("animation.frames", animation.frames, 1, 10000);
    if (field.frames) {
        const auto [first, last] = *field.frames;
        if (first < 0 || last < first || last - first >= 100000)
            violation("field.frames", "[first, last] with 0 <= first <= last and at most 100000 frames",
                      "[" + std::to_string(first) + ", " + std::to_string(last) + "]");
        if (animation.frames > 1)
            violation("animation.frames", "1 with an unsteady field sequence (field.frames): a sequence plays once, "
                      "it is not a loop", std::to_string(animation.frames));
    }
    if (!(field.fps > 0) || !std::isfinite(field.fps) || field.fps > 1e6) violation("field.fps", "in (0, 1e6]", fmt(field.fps));
    checkInt("threads", threads, 0, 1024);
}

void Recipe::validatePaths() const
{
    if (field.path.empty()) {
        throw lic::InputError("field.path: no input field given; pass --field FIELD.vdb or set field.path in the recipe");
    }
    if (output.path.empty()) {
        throw lic::InputError("output.path: no output file given; pass --out OUT.vdb or set output.path in the recipe");
    }
}

Recipe parseRecipe(const std::string& text, const std::string& source)
{
    json j;
    try {
        j = json::parse(text, nullptr, /*allow_exceptions=*/true, /*ignore_comments=*/true);
    } catch (const json::parse_error& e) {
        // Position from the byte offset; the reason is the parser's text after "column N: ".
        const std::size_t byte = std::min<std::size_t>(e.byte, text.size());
        std::size_t line = 1, column = 0;
        for (std::size_t i = 0; i < byte; ++i) {
            if (text[i] == '\n') {
                ++line;
                column = 0;
            } else {
                ++column;
            }
        }
        std::string reason = e.what();
        if (const auto pos = reason.find(": "); pos != std::string::npos) reason = reason.substr(pos + 2);
        throw lic::InputError(source + ": invalid JSON at line " + std::to_string(line) + ", column " +
            std::to_string(std::max<std::size_t>(column, 1)) + ": " + reason);
    } catch (const json::exception& e) {
        // Not a syntax error but a value the parser cannot hold (a number out of range, ...).
        std::string reason = e.what();
        if (const auto pos = reason.find("] "); pos != std::string::npos) reason = reason.substr(pos + 2);
        throw lic::InputError(source + ": invalid JSON: " + reason);
    }
    Recipe r = Recipe::fromJson(j, source);
    // A region of interest without its range would silently keep [0, 1] of the scalar's own units.
    if (const auto roi = j.find("roi"); roi != j.end() && roi->is_object() && !roi->contains("range")) {
        throw lic::InputError(source + ": roi.range is required: [lo, hi], the scalar's range to keep, in its "
                                       "own units");
    }
    try {
        r.validate();
    } catch (const lic::InputError& e) {
        throw lic::InputError(source + ": " + e.what());
    }
    return r;
}

Recipe loadRecipeFile(const std::string& path)
{
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
        throw lic::InputError("recipe file " + quote(path) + " not found; expected a JSON recipe file");
    }
    if (std::filesystem::is_directory(path, ec)) {
        throw lic::InputError("recipe file " + quote(path) + " is a directory; expected a JSON recipe file");
    }
    std::ifstream in(path, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    if (!in.good() && !in.eof()) throw lic::InputError("cannot read recipe file " + quote(path));
    return parseRecipe(text.str(), path);
}

const std::vector<std::string>& allowedValues(const std::string& keyPath)
{
    // The library's own name tables where it has one (engines, kernels, integrators, spot
    // distributions, noise filters), so a new value needs no change here.
    static const std::map<std::string, std::vector<std::string>> table{
        {"lic.engine", [] {
             std::vector<std::string> names{"auto"};
             for (const std::string& n : lic::listedNames(lic::engineNames())) names.push_back(n);
             return names;
         }()},
        {"lic.kernel", lic::listedNames(lic::kernelNames())},
        {"lic.integrator", lic::listedNames(lic::integratorNames())},
        {"input.type", {"noise", "spots"}},
        {"input.distribution", lic::listedNames(lic::spotDistributionNames())},
        {"input.noise_filter", lic::listedNames(lic::noiseFilterNames())},
        {"roi.mode", {"pre", "post"}},
        {"output.contrast", {"stretch", "none"}},
        {"field.format", inputFormatValues()},
        {"field.dtype", {"float32", "float64", "f4", "f8", "<f4", "<f8", ">f4", ">f8"}},
        {"field.mask", {"none", "zero"}},
        {"field.nan_policy", {"refuse", "zero"}},
    };
    static const std::vector<std::string> none;
    const auto it = table.find(keyPath);
    return it == table.end() ? none : it->second;
}

std::string suggestKey(const std::string& bad, const std::vector<std::string>& valid)
{
    auto lower = [](std::string s) {
        for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
        return s;
    };
    // Optimal string alignment distance: Levenshtein plus adjacent transpositions.
    auto distance = [](const std::string& a, const std::string& b) {
        std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
        for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
        for (std::size_t k = 0; k <= b.size(); ++k) d[0][k] = k;
        for (std::size_t i = 1; i <= a.size(); ++i) {
            for (std::size_t k = 1; k <= b.size(); ++k) {
                const std::size_t cost = a[i - 1] == b[k - 1] ? 0 : 1;
                d[i][k] = std::min({d[i - 1][k] + 1, d[i][k - 1] + 1, d[i - 1][k - 1] + cost});
                if (i > 1 && k > 1 && a[i - 1] == b[k - 2] && a[i - 2] == b[k - 1]) {
                    d[i][k] = std::min(d[i][k], d[i - 2][k - 2] + 1);
                }
            }
        }
        return d[a.size()][b.size()];
    };
    const std::string a = lower(bad);
    if (a.empty()) return "";
    const std::size_t limit = 1 + a.size() / 4; // 1 edit for short words, more for long ones
    std::string best;
    std::size_t bestDist = std::numeric_limits<std::size_t>::max();
    for (const auto& candidate : valid) {
        const std::string b = lower(candidate);
        std::size_t dist = distance(a, b);
        if (a.size() >= 3 && b.rfind(a, 0) == 0) dist = std::min(dist, std::size_t(1)); // a prefix: "len"
        if (dist <= limit && dist < a.size() && dist < bestDist) {
            best = candidate;
            bestDist = dist;
        }
    }
    return best;
}

} // namespace vdbexport

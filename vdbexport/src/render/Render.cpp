#include "vdbexport/render/Render.h"

#include "io/Quote.h"

#include "vdbexport/io/Numbers.h"
#include "vdbexport/io/FieldGrids.h"
#include "vdbexport/io/VdbReader.h"

#include <lic/composite/Colormap.h>
#include <lic/composite/OutputGrids.h>
#include <lic/util/Error.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <tuple>
#include <optional>
#include <sstream>

namespace vdbexport {

namespace fs = std::filesystem;

namespace {

using detail::q;

nlohmann::json vec(const openvdb::Vec3d& v) { return {v[0], v[1], v[2]}; }

using Clock = std::chrono::steady_clock;
double seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// The grids of one .vdb the renderer uses.
struct LoadedVolume
{
    lic::RenderVolume volume;
    std::vector<std::pair<std::string, std::string>> gridTypes;
};

openvdb::FloatGrid::Ptr readFloat(detail::VdbReader& reader, const std::string& path, const std::string& name,
                                  const std::string& type)
{
    if (type == openvdb::typeNameAsString<float>())
        return openvdb::gridPtrCast<openvdb::FloatGrid>(reader.readGrid(name));
    if (type == openvdb::typeNameAsString<double>()) {
        auto all = readScalarGrids(path);
        auto it = all.find(name);
        if (it != all.end()) return it->second;
    }
    throw lic::InputError("grid '" + name + "' in " + q(path) + " is " + type + "; expected a float grid");
}

openvdb::Vec3SGrid::Ptr readVec3(detail::VdbReader& reader, const std::string& path, const std::string& name,
                                 const std::string& type)
{
    if (type == openvdb::typeNameAsString<openvdb::Vec3s>())
        return openvdb::gridPtrCast<openvdb::Vec3SGrid>(reader.readGrid(name));
    if (detail::isVec3Type(type)) return readVelocityGrid(path, name);
    throw lic::InputError("grid '" + name + "' in " + q(path) + " is " + type + "; expected a vec3s grid");
}

LoadedVolume loadVolume(const std::string& path, bool wantHalo, bool wantScalar, bool wantTangent)
{
    openvdb::initialize();
    detail::VdbReader reader(path);
    LoadedVolume out;
    out.gridTypes = reader.gridTypes();
    auto typeOf = [&](const std::string& name) -> std::string {
        for (const auto& [n, t] : out.gridTypes)
            if (n == name) return t;
        return "";
    };
    using lic::OutputGrid;
    const std::string density = lic::outputGridName(OutputGrid::Density);
    const std::string dt = typeOf(density);
    if (dt.empty())
        throw lic::InputError(q(path) + " has no `density` grid (it has " + detail::listGrids(out.gridTypes) +
                              "); expected a licvdb bake with a float grid `density`");
    out.volume.density = readFloat(reader, path, density, dt);
    // The optional grids the renderer reads, each when present and wanted.
    auto floatGrid = [&](OutputGrid id, bool want, openvdb::FloatGrid::ConstPtr& to) {
        const std::string name = lic::outputGridName(id);
        if (want && !typeOf(name).empty()) to = readFloat(reader, path, name, typeOf(name));
    };
    auto vecGrid = [&](OutputGrid id, bool want, openvdb::Vec3SGrid::ConstPtr& to) {
        const std::string name = lic::outputGridName(id);
        if (want && !typeOf(name).empty()) to = readVec3(reader, path, name, typeOf(name));
    };
    // Always read `halo` when present: with --halos off it still marks a line bake (auto density scale).
    floatGrid(OutputGrid::Halo, wantHalo, out.volume.halo);
    // A colormap over `scalar` replaces `color`: do not read it then.
    vecGrid(OutputGrid::Color, !wantScalar, out.volume.color);
    floatGrid(OutputGrid::Scalar, wantScalar, out.volume.scalar);
    vecGrid(OutputGrid::Tangent, wantTangent, out.volume.tangent);
    return out;
}

std::string manifestDir(const std::string& manifest)
{
    const fs::path d = fs::path(manifest).parent_path();
    return d.empty() ? "." : d.string();
}

} // namespace

void applyRenderFlags(RenderJob& job, const RenderFlagStrings& f)
{
    if (!f.size.empty()) {
        const auto v = parseNumberList("--size", f.size, "W,H in pixels (e.g. 1024,768) or one number for a square");
        if (v.size() > 2) throw lic::InputError("--size \"" + f.size + "\" has " + std::to_string(v.size()) +
                                                " numbers; expected W,H in pixels");
        const double w = v[0], h = v.size() == 2 ? v[1] : v[0];
        if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 32768 || h > 32768)
            throw lic::InputError("--size \"" + f.size + "\" is out of range; expected whole numbers of pixels, 1 to 32768");
        job.camera.width = int(w);
        job.camera.height = int(h);
    }
    if (!f.view.empty()) job.view = lic::viewFromString(f.view);
    if (!f.halos.empty()) {
        if (f.halos == "on") job.settings.halos = true;
        else if (f.halos == "off") job.settings.halos = false;
        else throw lic::InputError("--halos \"" + f.halos + "\" is not valid; expected on or off");
    }
    if (!f.light.empty()) {
        if (f.light == "headlight") {
            job.settings.lighting.headlight = true;
        } else if (f.light == "off" || f.light == "none") {
            job.settings.lighting.enabled = false;
        } else {
            const auto v = parseNumberList("--light", f.light, "headlight, off, or a direction X,Y,Z towards the light");
            if (v.size() != 3 || openvdb::Vec3d(v[0], v[1], v[2]).length() == 0.0)
                throw lic::InputError("--light \"" + f.light +
                                      "\" is not valid; expected headlight, off, or a non-zero direction X,Y,Z towards the light");
            job.settings.lighting.headlight = false;
            job.settings.lighting.direction = openvdb::Vec3d(v[0], v[1], v[2]);
        }
    }
    if (f.densityRange == "auto") {
        job.densityRange = DensityRangeMode::Auto;
    } else if (!f.densityRange.empty()) {
        const auto v = parseNumberList("--density-range", f.densityRange, "LO,HI with 0 <= LO < HI, or auto");
        if (v.size() != 2 || !(v[0] >= 0.0 && v[0] < v[1]))
            throw lic::InputError("--density-range \"" + f.densityRange +
                                  "\" is not valid; expected LO,HI with 0 <= LO < HI, or auto");
        job.settings.densityLow = v[0];
        job.settings.densityHigh = v[1];
        job.densityRange = DensityRangeMode::Fixed;
    }
    if (!f.stereo.empty()) job.stereo = lic::stereoFromString(f.stereo);
}

namespace {

/// `fn(value, voxels)` for the active values of `grid`: each active leaf voxel once, then each
/// active tile with the number of voxels it covers. Always in the same order.
template<typename Fn>
void forEachActive(const openvdb::FloatGrid& grid, Fn&& fn)
{
    using TreeT = openvdb::FloatTree;
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        const float* values = leaf->buffer().data();
        for (auto on = leaf->getValueMask().beginOn(); on; ++on) fn(double(values[on.pos()]), std::uint64_t(1));
    }
    auto tile = grid.tree().cbeginValueOn();
    tile.setMaxDepth(TreeT::ValueOnCIter::LEAF_DEPTH - 1); // above the leaves: tiles only
    for (; tile; ++tile) fn(double(*tile), std::uint64_t(tile.getVoxelCount()));
}

/// The `q`-th percentile (0–100) of the values `bins` counts, `total` in all, bin i covering
/// [i·width, (i + 1)·width): the rank's position within its bin, interpolated linearly.
double percentileOf(const std::vector<std::uint64_t>& bins, std::uint64_t total, double width, double q)
{
    const double rank = q / 100.0 * double(total - 1); // 0-based, fractional
    std::uint64_t before = 0;
    for (std::size_t i = 0; i < bins.size(); ++i) {
        if (bins[i] == 0) continue;
        if (rank < double(before + bins[i])) return (double(i) + (rank - double(before) + 0.5) / double(bins[i])) * width;
        before += bins[i];
    }
    return double(bins.size()) * width;
}

} // namespace

AutoDensityRange autoDensityRange(const openvdb::FloatGrid& density)
{
    AutoDensityRange r;
    double max = 0.0;
    forEachActive(density, [&](double v, std::uint64_t n) {
        if (v > 0.0) {
            r.voxels += n;
            max = std::max(max, v);
        }
    });
    if (r.voxels == 0) return r; // nothing to see: the default window
    constexpr std::size_t kBins = 65536;
    const double width = max / double(kBins);
    std::vector<std::uint64_t> bins(kBins, 0);
    forEachActive(density, [&](double v, std::uint64_t n) {
        if (v > 0.0) bins[std::min(kBins - 1, std::size_t(v / width))] += n;
    });
    const auto round4 = [](double v) { return std::round(v * 1e4) / 1e4; };
    r.low = round4(percentileOf(bins, r.voxels, width, kAutoDensityLowPercentile));
    r.high = std::min(round4(percentileOf(bins, r.voxels, width, kAutoDensityHighPercentile)), round4(max));
    r.fromPercentiles = r.low < r.high && r.low < 1.0;
    if (!r.fromPercentiles) { // no spread the percentiles can see (constant, or saturated at the max)
        r.low = 0.0;
        r.high = max;
    }
    return r;
}

std::string imageFramePath(const std::string& imagePath, int frame, int frames)
{
    if (frames <= 1) return imagePath;
    const fs::path p(imagePath);
    char suffix[16];
    std::snprintf(suffix, sizeof suffix, "_%04d", frame);
    return (p.parent_path() / (p.stem().string() + suffix + p.extension().string())).string();
}

namespace {
/// The frame number a file name ends in (stem `OUT_0012` → OUT, 12), if it has one (4–9 digits).
std::optional<std::pair<std::string, int>> numberedStem(const std::string& stem)
{
    static const std::regex numbered("(.*)_([0-9]{4,9})");
    std::smatch m;
    if (!std::regex_match(stem, m, numbered)) return std::nullopt;
    return std::pair{m[1].str(), std::stoi(m[2].str())};
}
} // namespace

std::vector<std::string> renderInputs(const std::string& input, int frames)
{
    if (frames < 0 || frames > 100000)
        throw lic::InputError("--frames " + std::to_string(frames) + " is out of range; expected 1 to 100000");
    std::error_code ec;
    if (fs::path(input).extension() == ".json") {
        if (!fs::is_regular_file(input, ec))
            throw lic::InputError("manifest " + q(input) + " does not exist; expected a bake's manifest OUT.licvdb.json (or an older OUT.json) or a .vdb");
        nlohmann::json m;
        try {
            std::ifstream in(input);
            m = nlohmann::json::parse(in);
        } catch (const std::exception& e) {
            throw lic::InputError("cannot read manifest " + q(input) + ": " + e.what() +
                                  "; expected the JSON manifest a bake writes");
        }
        if (!m.is_object() || !m.contains("files") || !m["files"].is_array() || m["files"].empty())
            throw lic::InputError("manifest " + q(input) + " has no `files` list; expected the JSON manifest a bake writes");
        std::vector<std::string> files;
        for (const auto& f : m["files"]) {
            if (!f.is_string()) throw lic::InputError("manifest " + q(input) + ": `files` holds a non-string");
            const fs::path p(f.get<std::string>());
            files.push_back(p.is_absolute() ? p.string() : (fs::path(manifestDir(input)) / p).string());
        }
        if (frames > 0 && frames != int(files.size()))
            throw lic::InputError("--frames " + std::to_string(frames) + " contradicts manifest " + q(input) +
                                  ", which lists " + std::to_string(files.size()) + " files; omit --frames");
        return files;
    }
    if (frames <= 1) return {input};
    // A sequence: IN may be OUT_0001.vdb (its first frame) or OUT.vdb.
    const fs::path p(input);
    std::string stem = p.stem().string();
    int first = 1; // an unsteady sequence starts at its field's first frame: IN = OUT_0010.vdb
    if (const auto n = numberedStem(stem)) std::tie(stem, first) = *n;
    std::vector<std::string> files;
    for (int f = first; f < first + frames; ++f) {
        char suffix[16];
        std::snprintf(suffix, sizeof suffix, "_%04d", f);
        const std::string file = (p.parent_path() / (stem + suffix + p.extension().string())).string();
        if (!fs::exists(file, ec))
            throw lic::InputError("frame " + std::to_string(f) + " (" + std::to_string(f - first + 1) + " of " +
                                  std::to_string(frames) + ", " + q(file) + ") does not exist; expected a sequence " +
                                  stem + "_" + std::string(4 - std::min<std::size_t>(4, std::to_string(first).size()), '0') +
                                  std::to_string(first) + p.extension().string() + " …");
        files.push_back(file);
    }
    return files;
}

nlohmann::json cameraJson(const lic::Camera& c)
{
    const bool ortho = c.projection == lic::Projection::Orthographic;
    // Blender's camera looks down its local −Z with local +Y up: world matrix columns are
    // right, up, −forward, position. Euler XYZ (R = Rz·Ry·Rx).
    const openvdb::Vec3d z = -c.forward;
    const double r20 = c.right[2], r21 = c.up[2], r22 = z[2], r10 = c.right[1], r00 = c.right[0];
    double ex, ey, ez;
    const double cy = std::sqrt(r00 * r00 + r10 * r10);
    if (cy > 1e-9) {
        ex = std::atan2(r21, r22);
        ey = std::atan2(-r20, cy);
        ez = std::atan2(r10, r00);
    } else { // gimbal lock
        ex = std::atan2(-z[1], c.up[1]);
        ey = std::atan2(-r20, cy);
        ez = 0.0;
    }
    nlohmann::json m = nlohmann::json::array();
    for (int row = 0; row < 3; ++row)
        m.push_back({c.right[row], c.up[row], z[row], c.position[row]});
    m.push_back({0.0, 0.0, 0.0, 1.0});
    nlohmann::json j{{"projection", lic::toString(c.projection)},
                     {"position", vec(c.position)},
                     {"forward", vec(c.forward)},
                     {"up", vec(c.up)},
                     {"right", vec(c.right)},
                     {"target", vec(c.target)},
                     {"azimuth_degrees", c.azimuth},
                     {"elevation_degrees", c.elevation},
                     {"distance", c.distance},
                     {"image_size", {c.width, c.height}}};
    if (ortho) {
        j["ortho_width"] = c.orthoWidth;
        j["ortho_height"] = c.orthoHeight;
    } else {
        j["fov_y_degrees"] = c.fovY;
        j["fov_x_degrees"] = c.fovX();
    }
    nlohmann::json b{{"type", ortho ? "ORTHO" : "PERSP"},
                     {"matrix_world", m},
                     {"rotation_euler", {ex, ey, ez}},
                     {"rotation_mode", "XYZ"},
                     {"sensor_fit", "VERTICAL"},
                     {"resolution_x", c.width},
                     {"resolution_y", c.height},
                     {"pixel_aspect", 1.0}};
    if (ortho) b["ortho_scale"] = c.orthoHeight;
    else b["angle_y"] = c.fovY * 3.14159265358979323846 / 180.0;
    j["blender"] = b;
    return j;
}

namespace {

/// A colormap by name, or read from a value,r,g,b .csv file.
lic::Colormap loadColormap(const std::string& nameOrPath)
{
    std::error_code ec;
    if (!fs::is_regular_file(nameOrPath, ec)) return lic::Colormap::named(nameOrPath);
    std::ifstream in(nameOrPath);
    std::stringstream ss;
    ss << in.rdbuf();
    return lic::Colormap::fromCsv(ss.str(), nameOrPath);
}

/// What a render settles before it reads anything.
struct RenderPlan
{
    lic::RenderSettings settings;  ///< densityScale becomes the first frame's when it is auto
    bool autoScale = false;        ///< densityScale was 0 = auto
    lic::CameraSettings camera;
    DisplayTransform display;
    std::optional<AutoDensityRange> autoRange; ///< the window autoDensityRange chose on the first frame, if it did
    bool linearOut = false;        ///< an .exr: no display transform
    bool gifOut = false;           ///< --out is the .gif
};

/// @throw lic::InputError for any bad setting, before a file is read.
RenderPlan planRender(const RenderJob& job)
{
    if (job.output.empty()) throw lic::InputError("no output image; give --out IMAGE.png (or .exr)");
    RenderPlan plan;
    plan.linearOut = isSceneLinearPath(job.output);
    plan.gifOut = fs::path(job.output).extension() == ".gif";
    plan.settings = job.settings;
    if (!job.colormap.empty()) plan.settings.colormap = loadColormap(job.colormap);
    plan.settings.validate();
    plan.autoScale = plan.settings.densityScale == 0.0;
    plan.camera = job.camera;
    const auto [az, el] = lic::viewAngles(job.view.value_or(lic::View::Front));
    plan.camera.azimuth = job.azimuth.value_or(az);
    plan.camera.elevation = job.elevation.value_or(el);
    plan.camera.validate();
    if (!plan.linearOut || job.gif) {
        plan.display.config = findOcioConfig(job.ocioConfig);
        plan.display.view = viewFromFlag(job.viewTransform);
        toDisplay(lic::Image(1, 1), plan.display); // fail now on a bad config, not after rendering
    }
    if (job.gif && plan.gifOut) throw lic::InputError("--gif writes OUT.gif beside a sequence of images; --out is already a .gif");
    if (job.eyeSeparation && !(*job.eyeSeparation > 0.0))
        throw lic::InputError("--eye-separation must be > 0 (world units)");
    if (!(job.fps > 0.0 && job.fps <= 100.0)) throw lic::InputError("--fps must be in (0, 100]");
    return plan;
}

void add(lic::RenderStats& total, const lic::RenderStats& more)
{
    total.rays += more.rays;
    total.samples += more.samples;
    total.skippedBricks += more.skippedBricks;
}

/// What a render has done so far, frame by frame.
struct RenderRun
{
    std::vector<std::string> written; ///< image files, removed if the render fails
    std::vector<lic::Image> gifFrames;
    double tLoad = 0, tRender = 0, tWrite = 0;
    lic::RenderStats total;
    bool usedHalo = false, lit = false, colored = false;
    std::optional<lic::Camera> camera; ///< one camera for the whole sequence, framed on the first frame
    std::optional<std::pair<lic::Camera, lic::Camera>> eyes;
    double eyeSeparation = 0;
    std::vector<std::pair<std::string, std::string>> firstGrids;
};

/// The image of `caster` through the run's camera, or its stereo eyes put together.
lic::Image renderView(const lic::HaloRaycaster& caster, lic::StereoMode stereo, RenderRun& run, lic::Progress& progress)
{
    lic::RenderStats st;
    if (!run.eyes) {
        lic::Image img = caster.render(*run.camera, progress, &st);
        add(run.total, st);
        return img;
    }
    lic::RenderStats st2;
    const lic::Image l = caster.render(run.eyes->first, progress, &st);
    const lic::Image r = caster.render(run.eyes->second, progress, &st2);
    add(st, st2);
    add(run.total, st);
    return stereo == lic::StereoMode::SideBySide ? lic::sideBySide(l, r) : lic::anaglyph(l, r);
}

/// What a bake's `density` grid says its input texture was (`lic_input`: noise or spots), or "".
std::string bakeInput(const openvdb::GridBase& density)
{
    const auto m = density.getMetadata<openvdb::StringMetadata>("lic_input");
    return m ? m->value() : std::string();
}

/// Settle the density window on the first frame: automatic for `--density-range auto` and, by
/// default, for a dense noise bake; otherwise the window given (or 0,1).
void chooseDensityRange(const RenderJob& job, RenderPlan& plan, const openvdb::FloatGrid& density)
{
    const bool automatic = job.densityRange == DensityRangeMode::Auto ||
                           (job.densityRange == DensityRangeMode::ByBake && bakeInput(density) == "noise");
    if (!automatic) return;
    plan.autoRange = autoDensityRange(density);
    plan.settings.densityLow = plan.autoRange->low;
    plan.settings.densityHigh = plan.autoRange->high;
}

/// Load `input`, frame `f` (1-based), and render it; the grids and the raycaster are freed on
/// return, before the image is written, so the write's memory reuses theirs.
lic::Image loadAndRender(const RenderJob& job, RenderPlan& plan, const std::string& input, int f,
                         const openvdb::Vec3SGrid::Ptr& flow, lic::Progress& progress, RenderRun& run)
{
    lic::RenderSettings& settings = plan.settings;
    auto t0 = Clock::now();
    LoadedVolume lv = loadVolume(input, /*wantHalo=*/true, settings.colormap.has_value(), settings.lighting.enabled);
    if (f == 1) {
        run.firstGrids = lv.gridTypes;
        chooseDensityRange(job, plan, *lv.volume.density); // a sequence keeps the first frame's window
    }
    if (settings.lighting.enabled) lv.volume.flow = flow;
    lic::HaloRaycaster caster(lv.volume, settings, progress);
    run.tLoad += seconds(t0);
    run.usedHalo = caster.hasHalo();
    settings.densityScale = caster.settings().densityScale; // a sequence keeps the first frame's (auto) scale
    run.lit = caster.hasTangent() && settings.lighting.enabled;
    run.colored = caster.hasColor();
    if (!run.camera) {
        run.camera = lic::makeCamera(plan.camera, caster.worldBBox());
        run.eyeSeparation = job.eyeSeparation.value_or(run.camera->distance / 30.0);
        if (job.stereo != lic::StereoMode::None) run.eyes = lic::stereoPair(*run.camera, run.eyeSeparation);
    }
    t0 = Clock::now();
    lic::Image img = renderView(caster, job.stereo, run, progress);
    run.tRender += seconds(t0);
    return img;
}

/// Read, render and write (or keep for the GIF) frame `f` (1-based) of `inputs`.
void renderFrame(const RenderJob& job, RenderPlan& plan, const std::vector<std::string>& inputs, int f,
                 const openvdb::Vec3SGrid::Ptr& flow, lic::Progress& progress, RenderRun& run)
{
    const std::string& input = inputs[std::size_t(f - 1)];
    lic::Image img = loadAndRender(job, plan, input, f, flow, progress, run);
    auto t0 = Clock::now();
    if (plan.gifOut) {
        run.gifFrames.push_back(std::move(img));
    } else {
        // Images are numbered as their files (an unsteady sequence's field frames).
        const auto n = numberedStem(fs::path(input).stem().string());
        const std::string path = imageFramePath(job.output, n ? n->second : f, int(inputs.size()));
        writeImageAtomic(path, img, plan.display,
                         {{"Software", std::string("licvdb ") + LICVDB_VERSION},
                          {"ImageDescription", "licvdb render of " + input}});
        run.written.push_back(path);
        if (job.gif) run.gifFrames.push_back(std::move(img));
    }
    run.tWrite += seconds(t0);
}

/// The animated GIF: --out itself, or OUT.gif beside the images with --gif.
void writeGif(const RenderJob& job, const RenderPlan& plan, RenderRun& run)
{
    const auto t0 = Clock::now();
    if (plan.gifOut) {
        writeGifAtomic(job.output, run.gifFrames, plan.display, job.fps);
        run.written.push_back(job.output);
    } else if (job.gif) {
        fs::path g(job.output);
        g.replace_extension(".gif");
        writeGifAtomic(g.string(), run.gifFrames, plan.display, job.fps);
        run.written.push_back(g.string());
    }
    run.tWrite += seconds(t0);
}

nlohmann::json settingsJson(const RenderPlan& plan)
{
    const lic::RenderSettings& s = plan.settings;
    return {{"density_scale", s.densityScale},
            {"density_scale_auto", plan.autoScale},
            {"density_range", {s.densityLow, s.densityHigh}},
            {"density_range_auto", plan.autoRange.has_value()},
            {"density_range_percentiles", plan.autoRange && plan.autoRange->fromPercentiles
                                              ? nlohmann::json{kAutoDensityLowPercentile, kAutoDensityHighPercentile}
                                              : nlohmann::json(nullptr)},
            {"brightness", s.brightness},
            {"step_voxels", s.step},
            {"halo_strength", s.haloStrength},
            {"halo_threshold", s.haloThreshold},
            {"colormap", s.colormap ? nlohmann::json(s.colormap->name()) : nlohmann::json(nullptr)},
            {"light", s.lighting.headlight ? nlohmann::json("headlight") : vec(s.lighting.direction)},
            {"view_transform", plan.linearOut ? nlohmann::json(nullptr) : nlohmann::json(plan.display.view)},
            {"ocio_config", plan.display.config.empty() ? nlohmann::json(nullptr) : nlohmann::json(plan.display.config)},
            {"threads", s.threads}};
}

/// The summary `licvdb render --json` prints.
nlohmann::json summaryJson(const RenderJob& job, const RenderPlan& plan, const std::vector<std::string>& inputs,
                           const RenderRun& run, Clock::time_point tStart)
{
    nlohmann::json grids = nlohmann::json::array();
    for (const auto& [n, t] : run.firstGrids) grids.push_back({{"name", n}, {"type", t}});
    const int width = plan.camera.width, height = plan.camera.height;
    nlohmann::json summary = {
        {"input", job.input},
        {"inputs", inputs},
        {"output", job.output},
        {"files", run.written},
        {"frames", int(inputs.size())},
        {"size", {width, height}},
        {"camera", cameraJson(*run.camera)},
        {"stereo", nullptr},
        {"grids", grids},
        {"halos", run.usedHalo},
        {"illuminated", run.lit},
        {"colored", run.colored},
        {"settings", settingsJson(plan)},
        {"stats",
         {{"rays", run.total.rays},
          {"samples", run.total.samples},
          {"samples_per_ray", run.total.rays ? double(run.total.samples) / double(run.total.rays) : 0.0},
          {"skipped_bricks", run.total.skippedBricks}}},
        {"seconds", {{"load", run.tLoad}, {"render", run.tRender}, {"write", run.tWrite}, {"total", seconds(tStart)}}},
    };
    summary["image_size"] = {width, height};
    if (run.eyes) {
        summary["stereo"] = {{"mode", lic::toString(job.stereo)},
                             {"eye_separation", run.eyeSeparation},
                             {"left", cameraJson(run.eyes->first)},
                             {"right", cameraJson(run.eyes->second)}};
        if (job.stereo == lic::StereoMode::SideBySide) summary["image_size"] = {2 * width, height};
    }
    return summary;
}

} // namespace

nlohmann::json render(const RenderJob& job, lic::Progress& progress)
{
    const auto tStart = Clock::now();
    RenderPlan plan = planRender(job); // everything cheap is checked before anything is read
    const std::vector<std::string> inputs = renderInputs(job.input, job.frames);
    if (job.gif && inputs.size() < 2 && !plan.gifOut)
        throw lic::InputError("--gif needs a sequence (--frames N or a manifest listing several files)");
    openvdb::Vec3SGrid::Ptr flow;
    if (!job.field.empty()) flow = readVelocityGrid(job.field);

    RenderRun run;
    try {
        for (int f = 1; f <= int(inputs.size()); ++f) renderFrame(job, plan, inputs, f, flow, progress, run);
        writeGif(job, plan, run);
    } catch (...) {
        for (const auto& p : run.written) {
            std::error_code ec;
            fs::remove(p, ec);
        }
        throw;
    }
    return summaryJson(job, plan, inputs, run, tStart);
}

} // namespace vdbexport

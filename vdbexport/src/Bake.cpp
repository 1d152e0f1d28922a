#include "vdbexport/Bake.h"

#include "vdbexport/VdbIO.h"

#include "lic/Animation.h"
#include "lic/Colormap.h"
#include "lic/Contrast.h"
#include "lic/Engine.h"
#include "lic/Error.h"
#include "lic/Noise.h"
#include "lic/Scalars.h"

#include <openvdb/tools/Interpolation.h>

#include <openvdb/openvdb.h>

#include <tbb/parallel_for.h>

#include <chrono>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace vdbexport {

namespace fs = std::filesystem;

std::string framePath(const std::string& vdbPath, int frame, int frames)
{
    if (frames <= 1) return vdbPath;
    fs::path p(vdbPath);
    char suffix[16];
    std::snprintf(suffix, sizeof suffix, "_%04d", frame);
    const std::string ext = p.extension() == ".vdb" ? ".vdb" : "";
    const fs::path stem = ext.empty() ? p.filename() : p.stem();
    return (p.parent_path() / (stem.string() + suffix + ".vdb")).string();
}

std::string manifestPath(const std::string& vdbPath)
{
    fs::path p(vdbPath);
    if (p.extension() == ".vdb") p.replace_extension(".json");
    else p += ".json";
    return p.string();
}

namespace {

void requireNotYet(bool used, const std::string& what)
{
    if (used) {
        throw lic::InputError(what + " is not available in this version of licvdb yet; remove it "
                                     "from the recipe or command line (see `licvdb help bake`)");
    }
}

/// Refuse recipe features that later releases add, rather than silently ignoring them.
void checkSupported(const Recipe& r)
{
    requireNotYet(r.input.type != "noise", "input.type (--input) \"" + r.input.type + "\"");
    requireNotYet(r.roi.has_value(), "roi");
    requireNotYet(r.width.has_value(), "width");
    requireNotYet(r.lic.engine == "splat", "lic.engine \"splat\"");
    requireNotYet(r.output.writeSeries, "output.write_series");
}

void checkOutputDirectory(const std::string& out)
{
    fs::path dir = fs::path(out).parent_path();
    if (dir.empty()) dir = ".";
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) {
        throw lic::InputError("output directory \"" + dir.string() + "\" does not exist (for --out " + out + ")");
    }
    if (fs::is_directory(out, ec)) {
        throw lic::InputError("output path \"" + out + "\" is a directory; expected a .vdb file name");
    }
}

nlohmann::json bboxJson(const openvdb::BBoxd& b)
{
    return {{b.min()[0], b.min()[1], b.min()[2]}, {b.max()[0], b.max()[1], b.max()[2]}};
}

/// World bounds of a grid's active voxels' extents (index bbox ± ½ voxel through the transform).
openvdb::BBoxd worldBBoxOf(const openvdb::GridBase& grid)
{
    const openvdb::CoordBBox ib = grid.evalActiveVoxelBoundingBox();
    return grid.transform().indexToWorld(
        openvdb::BBoxd(ib.min().asVec3d() - openvdb::Vec3d(0.5), ib.max().asVec3d() + openvdb::Vec3d(0.5)));
}

lic::Colormap loadColormap(const std::string& spec)
{
    if (fs::path(spec).extension() != ".csv") return lic::Colormap::named(spec);
    std::ifstream in(spec);
    if (!in) throw lic::InputError("colormap LUT file \"" + spec + "\" cannot be read");
    std::stringstream text;
    text << in.rdbuf();
    return lic::Colormap::fromCsv(text.str(), spec);
}

/// The colour scalar sampled trilinearly at every active output voxel centre. Positions are
/// clamped to the scalar's active bounding box (as the velocity sampler does), so the outer half
/// voxel repeats the edge value instead of blending with the background.
std::vector<float> sampleScalar(const openvdb::FloatGrid& scalar, const lic::OutputDomain& domain)
{
    std::vector<float> out(domain.slotCount(), 0.0f);
    const openvdb::CoordBBox bb = scalar.evalActiveVoxelBoundingBox();
    const openvdb::Vec3d lo = bb.min().asVec3d(), hi = bb.max().asVec3d();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, domain.blockCount()), [&](const auto& r) {
        const auto acc = scalar.getConstAccessor();
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            const auto& mask = domain.blockMask(b);
            for (std::size_t off = mask._Find_first(); off < mask.size(); off = mask._Find_next(off)) {
                const std::size_t s = b * lic::OutputDomain::kBlockVoxels + off;
                openvdb::Vec3d idx = scalar.worldToIndex(domain.worldOf(domain.coordOf(s)));
                for (int a = 0; a < 3; ++a) idx[a] = std::clamp(idx[a], lo[a], hi[a]);
                float v = 0.0f;
                openvdb::tools::BoxSampler::sample(acc, idx, v);
                out[s] = v;
            }
        }
    });
    return out;
}

/// Robust automatic range: the 1st and 99th percentiles over active voxels.
std::array<double, 2> autoRange(const std::vector<float>& values, const lic::OutputDomain& domain)
{
    std::vector<float> v;
    v.reserve(domain.activeVoxelCount());
    for (std::size_t s = 0; s < values.size(); ++s)
        if (domain.isActive(s) && std::isfinite(values[s])) v.push_back(values[s]);
    if (v.empty()) return {0.0, 1.0};
    auto pct = [&](double q) {
        const std::size_t k = std::min(v.size() - 1, std::size_t(q * double(v.size() - 1) + 0.5));
        std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
        return double(v[k]);
    };
    double lo = pct(0.01), hi = pct(0.99);
    if (!(hi > lo)) hi = lo + 1.0; // constant scalar: everything maps to the low end
    return {lo, hi};
}

} // namespace

nlohmann::json bake(const Recipe& recipe, lic::Progress& progress)
{
    using Clock = std::chrono::steady_clock;
    auto seconds = [](Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); };
    const auto t0 = Clock::now();

    recipe.validate();
    recipe.validatePaths();
    checkSupported(recipe);
    checkOutputDirectory(recipe.output.path);
    openvdb::initialize();

    lic::LicSettings settings;
    settings.engine = lic::engineFromString(recipe.lic.engine);
    settings.integrator = lic::integratorFromString(recipe.lic.integrator);
    settings.kernel = lic::kernelFromString(recipe.lic.kernel);
    settings.decay = recipe.lic.decay;
    settings.length = recipe.lic.length;
    settings.step = recipe.lic.step;
    settings.tolerance = recipe.lic.tolerance;
    settings.minHits = recipe.lic.minHits;
    settings.threads = recipe.threads;
    const int frames = recipe.animation.frames;
    settings.ripple = frames > 1;
    settings.validate();

    // 1. Field.
    std::string gridName;
    openvdb::Vec3SGrid::Ptr grid = readVelocityGrid(recipe.field.path, recipe.field.grid, &gridName);
    const lic::VelocityField field(grid);
    const lic::OutputDomain domain(field, recipe.output.upsample);
    const double tRead = seconds(t0);

    // 2. Input texture and convolution.
    const auto t1 = Clock::now();
    const lic::NoiseTexture noise(recipe.input.seed, domain.indexBBox(),
                                  lic::noiseFilterFromString(recipe.input.noiseFilter));
    const double tInput = seconds(t1);
    lic::LicResult result = lic::convolve(field, domain, noise, settings, progress);

    // 3. Contrast.
    const auto t2 = Clock::now();
    // Frame f of a loop (or the still); every frame gets frame 1's contrast mapping, so the
    // loop does not flicker.
    const bool stretch = recipe.output.contrast == "stretch";
    auto frameDensity = [&](int f) {
        return frames > 1 ? lic::composeFrame(result, 1, 0, f, frames) : result.channels[0];
    };
    std::vector<float> density = frameDensity(1);
    const lic::ChannelStats raw = stretch ? lic::contrastStretch(domain, density) : lic::channelStats(domain, density);

    // 4. Grids and metadata.
    const nlohmann::json resolved = recipe.toJson();
    openvdb::MetaMap densityMeta; // on `density` of every frame
    densityMeta.insertMeta("licvdb_version", openvdb::StringMetadata(LICVDB_VERSION));
    densityMeta.insertMeta("licvdb_recipe", openvdb::StringMetadata(resolved.dump()));
    densityMeta.insertMeta("licvdb_field_grid", openvdb::StringMetadata(gridName));
    densityMeta.insertMeta("lic_engine", openvdb::StringMetadata(recipe.lic.engine));
    densityMeta.insertMeta("lic_kernel", openvdb::StringMetadata(recipe.lic.kernel));
    densityMeta.insertMeta("lic_length", openvdb::FloatMetadata(float(recipe.lic.length)));
    densityMeta.insertMeta("lic_step", openvdb::FloatMetadata(float(recipe.lic.step)));
    if (settings.kernel == lic::KernelType::Exp) {
        densityMeta.insertMeta("lic_decay", openvdb::FloatMetadata(float(recipe.lic.decay)));
        densityMeta.insertMeta("lic_orientation", openvdb::StringMetadata("bright head downstream"));
    }
    densityMeta.insertMeta("lic_frames", openvdb::Int32Metadata(frames));
    densityMeta.insertMeta("lic_cyclic", openvdb::BoolMetadata(frames > 1));
    auto makeDensity = [&](const std::vector<float>& values, int frame) {
        openvdb::FloatGrid::Ptr g = domain.makeGrid(values, "density");
        for (auto it = densityMeta.beginMeta(); it != densityMeta.endMeta(); ++it) g->insertMeta(it->first, *it->second);
        g->insertMeta("lic_frame", openvdb::Int32Metadata(frame));
        return g;
    };
    openvdb::GridPtrVec grids; // grids shared by every frame (density is added per frame)
    if (recipe.output.writeInput) {
        std::vector<float> input(domain.slotCount(), 0.0f);
        for (std::size_t s = 0; s < input.size(); ++s)
            if (domain.isActive(s)) input[s] = noise.voxel(domain.coordOf(s));
        grids.push_back(domain.makeGrid(input, "input"));
    }
    if (recipe.output.writeTangent) {
        // Unit flow direction at each voxel centre (zero at critical points), for illuminated
        // lines in renderers.
        std::vector<openvdb::Vec3s> tangent(domain.slotCount(), openvdb::Vec3s(0.0f));
        const double minSpeed = field.maxSpeed() * 1e-6;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tangent.size()), [&](const auto& range) {
            for (std::size_t s = range.begin(); s != range.end(); ++s) {
                if (!domain.isActive(s)) continue;
                openvdb::Vec3d v;
                if (!field.sample(domain.worldOf(domain.coordOf(s)), v)) continue;
                const double len = v.length();
                if (len > minSpeed) tangent[s] = openvdb::Vec3s(v / len);
            }
        });
        grids.push_back(domain.makeGrid<openvdb::Vec3SGrid>(tangent, "tangent"));
    }
    nlohmann::json colorJson = nullptr;
    if (recipe.color) {
        const lic::Colormap cmap = loadColormap(recipe.color->colormap);
        // Derived scalars need no second read of the field file.
        const auto& derived = lic::derivedScalarNames();
        const bool isDerived = std::find(derived.begin(), derived.end(), recipe.color->scalar) != derived.end();
        const auto fileScalars = isDerived ? std::map<std::string, openvdb::FloatGrid::Ptr>{}
                                           : readScalarGrids(recipe.field.path);
        const openvdb::FloatGrid::ConstPtr scalarGrid = lic::resolveScalar(*grid, fileScalars, recipe.color->scalar);
        std::vector<float> values = sampleScalar(*scalarGrid, domain);
        const std::array<double, 2> range = recipe.color->range ? *recipe.color->range : autoRange(values, domain);
        std::vector<openvdb::Vec3s> color(domain.slotCount(), openvdb::Vec3s(0.0f));
        const double inv = 1.0 / (range[1] - range[0]);
        for (std::size_t s = 0; s < values.size(); ++s) {
            if (!domain.isActive(s)) continue;
            const double t = std::clamp((double(values[s]) - range[0]) * inv, 0.0, 1.0);
            values[s] = float(t);
            color[s] = openvdb::Vec3s(cmap.linear(t));
        }
        grids.push_back(domain.makeGrid<openvdb::Vec3SGrid>(color, "color"));
        grids.back()->setVectorType(openvdb::VEC_INVARIANT);
        grids.back()->insertMeta("licvdb_color_space", openvdb::StringMetadata("scene-linear Rec.709"));
        grids.push_back(domain.makeGrid(values, "scalar"));
        densityMeta.insertMeta("lic_color_scalar", openvdb::StringMetadata(recipe.color->scalar));
        densityMeta.insertMeta("lic_colormap", openvdb::StringMetadata(cmap.name()));
        densityMeta.insertMeta("lic_color_range", openvdb::Vec2DMetadata(openvdb::Vec2d(range[0], range[1])));
        nlohmann::json points = nlohmann::json::array();
        for (const auto& [pos, c] : cmap.points()) points.push_back({pos, c[0], c[1], c[2]});
        colorJson = {{"scalar", recipe.color->scalar}, {"name", cmap.name()}, {"range", {range[0], range[1]}},
                     {"space", "sRGB"}, {"points", points}};
    }
    const double tCompose = seconds(t2);

    // 5. Files, then the manifest (a manifest never points at a missing file). A loop is written
    // as OUT_0001.vdb … OUT_NNNN.vdb; if any frame fails, the frames already written are removed.
    const auto t3 = Clock::now();
    std::vector<std::string> paths;
    for (int f = 1; f <= frames; ++f) paths.push_back(framePath(recipe.output.path, f, frames));
    openvdb::GridPtrVec firstGrids;
    try {
        for (int f = 1; f <= frames; ++f) {
            std::vector<float> d = f == 1 ? density : frameDensity(f);
            if (f > 1 && stretch) lic::applyContrast(domain, d, raw);
            openvdb::GridPtrVec fileGrids{makeDensity(d, f)};
            fileGrids.insert(fileGrids.end(), grids.begin(), grids.end());
            if (f == 1) firstGrids = fileGrids;
            writeVdbAtomic(paths[std::size_t(f - 1)], fileGrids);
        }
    } catch (...) {
        for (const auto& p : paths) {
            std::error_code ec;
            fs::remove(p, ec);
        }
        throw;
    }
    nlohmann::json manifest;
    manifest["licvdb_version"] = LICVDB_VERSION;
    manifest["recipe"] = resolved;
    manifest["frames"] = frames;
    manifest["cyclic"] = frames > 1;
    manifest["files"] = nlohmann::json::array();
    for (const auto& p : paths) manifest["files"].push_back(fs::path(p).filename().string());
    manifest["voxel_size"] = domain.voxelSize();
    manifest["colormap"] = colorJson;
    manifest["range"] = colorJson.is_null() ? nlohmann::json(nullptr) : colorJson["range"];
    manifest["grids"] = nlohmann::json::array();
    for (const auto& g : firstGrids) {
        const openvdb::Vec3d vs = g->voxelSize();
        manifest["grids"].push_back({{"name", g->getName()},
                                     {"type", g->valueType()},
                                     {"active_voxels", g->activeVoxelCount()},
                                     {"voxel_size", {vs[0], vs[1], vs[2]}},
                                     {"world_bbox", bboxJson(worldBBoxOf(*g))}});
    }
    writeTextAtomic(manifestPath(recipe.output.path), manifest.dump(2) + "\n");
    const double tWrite = seconds(t3);

    const lic::LicStats& st = result.stats;
    return {
        {"output", recipe.output.path},
        {"files", paths},
        {"frames", frames},
        {"manifest", manifestPath(recipe.output.path)},
        {"field", {{"path", recipe.field.path}, {"grid", gridName},
                   {"active_voxels", field.activeVoxelCount()}, {"world_bbox", bboxJson(field.worldBBox())}}},
        {"engine", recipe.lic.engine},
        {"output_voxels", st.voxels},
        {"output_bbox", {{domain.indexBBox().min()[0], domain.indexBBox().min()[1], domain.indexBBox().min()[2]},
                         {domain.indexBBox().max()[0], domain.indexBBox().max()[1], domain.indexBBox().max()[2]}}},
        {"streamlines", st.streamlines},
        {"samples", st.samples},
        {"samples_per_voxel", st.samplesPerVoxel()},
        {"deposits", st.deposits},
        {"rounds", st.rounds},
        {"raw_mean", raw.mean},
        {"raw_stddev", raw.stddev},
        {"seconds", {{"read", tRead}, {"input", tInput}, {"convolve", st.seconds}, {"compose", tCompose},
                     {"write", tWrite}, {"total", seconds(t0)}}},
    };
}

} // namespace vdbexport

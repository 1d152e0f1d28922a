#include "vdbexport/Bake.h"

#include "vdbexport/FieldInput.h"
#include "vdbexport/VdbIO.h"

#include "lic/Animation.h"
#include "lic/Colormap.h"
#include "lic/Contrast.h"
#include "lic/Engine.h"
#include "lic/Error.h"
#include "lic/Noise.h"
#include "lic/Region.h"
#include "lic/Scalars.h"
#include "lic/Spots.h"

#include <openvdb/tools/Interpolation.h>

#include <openvdb/openvdb.h>

#include <tbb/parallel_for.h>

#include <chrono>
#include <optional>
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

void checkNotOverwritten(const Recipe& recipe, const std::string& path, const std::string& what)
{
    if (path.empty()) return;
    std::error_code ec;
    const fs::path input = fs::weakly_canonical(path, ec);
    if (ec) return; // cannot be resolved: reading it will report the problem
    std::vector<std::string> outputs{manifestPath(recipe.output.path)};
    for (int f = 1; f <= recipe.animation.frames; ++f)
        outputs.push_back(framePath(recipe.output.path, f, recipe.animation.frames));
    for (const auto& out : outputs) {
        std::error_code e1, e2;
        const bool same = fs::equivalent(path, out, e1) || fs::weakly_canonical(out, e2) == input;
        if (same && !e2) {
            throw lic::InputError("the bake would overwrite " + what + " \"" + path + "\" with \"" + out +
                                  "\"; choose another --out");
        }
    }
}

namespace {

void requireNotYet(bool used, const std::string& what)
{
    if (used) {
        throw lic::InputError(what + " is not available in this version of licvdb yet; remove it "
                                     "from the recipe or command line (see `licvdb help bake`)");
    }
}

/// Refuse recipe features that later releases add, and combinations that mean nothing, rather
/// than silently ignoring them.
void checkSupported(const Recipe& r)
{
    requireNotYet(r.lic.engine == "splat", "lic.engine \"splat\"");
    const bool spots = r.input.type == "spots";
    if (!spots && r.width) {
        throw lic::InputError("width needs spot input (input.type \"spots\", --input spots): line width "
                              "comes from the spot radii input.radii");
    }
    if (!spots && r.output.writeSeries) {
        throw lic::InputError("output.write_series (--write-series) needs spot input (input.type \"spots\")");
    }
    if (!spots && r.input.surface) {
        throw lic::InputError("input.surface places spots: it needs input.type \"spots\" (--input spots)");
    }
    if (spots && r.input.radii.size() > 4) {
        throw lic::InputError("input.radii has " + std::to_string(r.input.radii.size()) +
                              " radii; at most 4 width levels are supported");
    }
    if (spots && r.input.radii.size() > 1 && !r.width && !r.output.writeSeries) {
        throw lic::InputError("input.radii has " + std::to_string(r.input.radii.size()) +
                              " radii but nothing uses the wider levels: add a width scalar (width.scalar, "
                              "--width SCALAR) or output.write_series (--write-series), or give one radius");
    }
}

/// Voxels of a spot bake whose line and halo are both at most this stay inactive (1% of a line
/// core: invisible in any renderer, and well below the raycaster's halo threshold of 0.05).
constexpr float kSparseEpsilon = 0.01f;

/// Trilinear value of a scalar grid at world positions, clamped to its active bounding box (as the
/// velocity sampler does). Thread-safe: one accessor per call.
class ScalarProbe
{
public:
    explicit ScalarProbe(const openvdb::FloatGrid& g) : mGrid(g)
    {
        const openvdb::CoordBBox bb = g.evalActiveVoxelBoundingBox();
        mLo = bb.min().asVec3d();
        mHi = bb.max().asVec3d();
    }
    float at(const openvdb::Vec3d& world) const
    {
        openvdb::Vec3d idx = mGrid.worldToIndex(world);
        for (int a = 0; a < 3; ++a) idx[a] = std::clamp(idx[a], mLo[a], mHi[a]);
        return openvdb::tools::BoxSampler::sample(mGrid.tree(), idx);
    }

private:
    const openvdb::FloatGrid& mGrid;
    openvdb::Vec3d mLo, mHi;
};

/// The spot centres of a bake (output index space) and their intensities: placed by the
/// distribution over the output box, or evenly on the ridge surface of `surface`; only spots on
/// active output voxels are kept; with a pre-mode ROI each spot is weighted by the mask at its
/// centre and spots outside the region are dropped.
lic::SpotSet makeSpotSet(const Recipe& r, const lic::OutputDomain& domain, const openvdb::FloatGrid* roiPre,
                         const openvdb::FloatGrid* surface)
{
    std::vector<openvdb::Vec3d> centers;
    if (surface) {
        std::vector<openvdb::Vec3d> candidates = lic::ridgePoints(*surface, r.input.surface->threshold);
        for (auto& c : candidates) c = domain.map().toIndex(c);
        if (candidates.empty()) {
            throw lic::InputError("input.surface: the scalar '" + r.input.surface->scalar +
                                  "' has no ridge above threshold " + std::to_string(r.input.surface->threshold) +
                                  "; lower the threshold (see `licvdb info` for the field's grids)");
        }
        centers = lic::selectEvenly(candidates, lic::kPoissonRadius * r.input.spacing, r.input.seed);
    } else {
        const openvdb::CoordBBox ib = domain.indexBBox();
        const openvdb::BBoxd box(ib.min().asVec3d() - openvdb::Vec3d(0.5), ib.max().asVec3d() + openvdb::Vec3d(0.5));
        centers = lic::placeSpots({lic::spotDistributionFromString(r.input.distribution), r.input.spacing,
                                   r.input.jitter, r.input.seed},
                                  box);
    }
    std::optional<ScalarProbe> probe;
    if (roiPre) probe.emplace(*roiPre);
    lic::SpotSet set;
    for (const auto& c : centers) {
        if (domain.slotOf(lic::OutputDomain::nearestVoxel(c)) < 0) continue;
        float w = 1.0f;
        if (probe) w = lic::roiWeight(probe->at(domain.map().toWorld(c)), r.roi->range[0], r.roi->range[1]);
        if (w <= 0.0f) continue;
        set.centers.push_back(c);
        set.weights.push_back(w);
    }
    return set;
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
    checkNotOverwritten(recipe, recipe.field.path, "the input field");
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
    // Any format (vdb, npy, vti, vtk, raw), prepared (NaN policy, crop, mask, resample);
    // the file's scalar grids come with it.
    const LoadedField loaded = loadField(recipe.field);
    const std::string gridName = loaded.gridName;
    openvdb::Vec3SGrid::Ptr grid = loaded.velocity;
    const lic::VelocityField field(grid);
    const lic::OutputDomain domain(field, recipe.output.upsample);
    const double tRead = seconds(t0);

    // 2. Scalars, region of interest, input texture and convolution.
    const auto t1 = Clock::now();
    // Scalars by name: derived, a float grid of the field file, or NAME-gradient = |∇NAME|.
    std::map<std::string, openvdb::FloatGrid::ConstPtr> scalarCache;
    auto scalarByName = [&](const std::string& name) -> openvdb::FloatGrid::ConstPtr {
        if (auto it = scalarCache.find(name); it != scalarCache.end()) return it->second;
        static const std::string kGradient = "-gradient";
        openvdb::FloatGrid::ConstPtr g;
        if (name.size() > kGradient.size() && name.ends_with(kGradient)) {
            const auto base = lic::resolveScalar(*grid, loaded.scalars, name.substr(0, name.size() - kGradient.size()));
            g = lic::gradientMagnitude(*base, name);
        } else {
            g = lic::resolveScalar(*grid, loaded.scalars, name);
        }
        return scalarCache[name] = g;
    };
    const bool spots = recipe.input.type == "spots";
    const bool roiPre = recipe.roi && recipe.roi->mode == "pre";
    const bool roiPost = recipe.roi && recipe.roi->mode == "post";
    openvdb::FloatGrid::ConstPtr roiGrid;
    std::vector<float> roiMask; // per slot, [0, 1]
    if (recipe.roi) {
        roiGrid = scalarByName(recipe.roi->scalar);
        roiMask = sampleScalar(*roiGrid, domain);
        for (float& v : roiMask) v = lic::roiWeight(v, recipe.roi->range[0], recipe.roi->range[1]);
    }
    std::optional<lic::NoiseTexture> noise;
    lic::SpotSet spotSet;
    lic::LicResult result;
    double tInput = 0.0;
    if (spots) {
        spotSet = makeSpotSet(recipe, domain, roiPre ? roiGrid.get() : nullptr,
                              recipe.input.surface ? scalarByName(recipe.input.surface->scalar).get() : nullptr);
        tInput = seconds(t1);
        result = lic::convolveSpots(field, domain, spotSet, recipe.input.radii, recipe.input.haloScale, settings,
                                    progress);
    } else {
        noise.emplace(recipe.input.seed, domain.indexBBox(), lic::noiseFilterFromString(recipe.input.noiseFilter));
        if (roiPre) {
            // Pre-mask: the noise itself is weighted, so the region's edge runs along the flow.
            const ScalarProbe probe(*roiGrid);
            const auto& roi = *recipe.roi;
            noise->multiply([&](const openvdb::Coord& ijk) {
                return lic::roiWeight(probe.at(domain.worldOf(ijk)), roi.range[0], roi.range[1]);
            });
        }
        tInput = seconds(t1);
        result = lic::convolve(field, domain, *noise, settings, progress);
    }

    // 3. Compositing and normalisation.
    const auto t2 = Clock::now();
    const bool stretch = recipe.output.contrast == "stretch";
    const int K = int(recipe.input.radii.size());
    const int C = spots ? 2 * K : 1; // texture channels
    auto channel = [&](int c, int f) {
        return frames > 1 ? lic::composeFrame(result, C, c, f, frames) : result.channels[std::size_t(c)];
    };
    // Noise: every frame gets frame 1's contrast mapping, so the loop does not flicker.
    lic::ChannelStats raw;
    // Spots: each level is divided by the peak a single spot gives on a straight line, so line
    // cores are 1 at every width; halos by their own peak, then raised to at least their line.
    std::vector<double> linePeak(std::size_t(K), 1.0), haloPeak(std::size_t(K), 1.0);
    if (spots && stretch) {
        for (int k = 0; k < K; ++k) {
            linePeak[std::size_t(k)] = lic::spotPeak(settings, recipe.input.radii[std::size_t(k)]);
            haloPeak[std::size_t(k)] = lic::spotPeak(settings, recipe.input.radii[std::size_t(k)] * recipe.input.haloScale);
        }
    }
    std::vector<float> widthT; // per slot: 0 = narrowest level … 1 = widest
    std::array<double, 2> widthRange{0, 1};
    if (recipe.width) {
        widthT = sampleScalar(*scalarByName(recipe.width->scalar), domain);
        widthRange = recipe.width->range ? *recipe.width->range : autoRange(widthT, domain);
        const double inv = 1.0 / (widthRange[1] - widthRange[0]);
        for (float& v : widthT) {
            const double t = std::clamp((double(v) - widthRange[0]) * inv, 0.0, 1.0);
            v = float(recipe.width->invert ? 1.0 - t : t);
        }
    }
    struct Frame
    {
        std::vector<float> density, halo;
        std::vector<std::vector<float>> lines, halos; // per level, for write_series
    };
    auto composeFrameGrids = [&](int f) {
        Frame fr;
        if (!spots) {
            fr.density = channel(0, f);
            if (f == 1) raw = stretch ? lic::contrastStretch(domain, fr.density) : lic::channelStats(domain, fr.density);
            else if (stretch) lic::applyContrast(domain, fr.density, raw);
        } else {
            for (int k = 0; k < K; ++k) {
                fr.lines.push_back(channel(k, f));
                fr.halos.push_back(channel(K + k, f));
                auto& line = fr.lines.back();
                auto& halo = fr.halos.back();
                const float li = float(1.0 / linePeak[std::size_t(k)]), hi = float(1.0 / haloPeak[std::size_t(k)]);
                for (std::size_t s = 0; s < line.size(); ++s) {
                    line[s] = std::clamp(line[s] * li, 0.0f, 1.0f);
                    halo[s] = std::max(std::clamp(halo[s] * hi, 0.0f, 1.0f), line[s]); // halo ⊇ line
                }
            }
            if (recipe.width && K > 1) {
                // Blend the two levels around t·(K − 1): continuous in t, so no seams.
                fr.density.assign(domain.slotCount(), 0.0f);
                fr.halo.assign(domain.slotCount(), 0.0f);
                for (std::size_t s = 0; s < fr.density.size(); ++s) {
                    const double u = double(widthT[s]) * double(K - 1);
                    const int k0 = std::min(K - 2, int(u));
                    const float w = float(u - k0);
                    fr.density[s] = (1.0f - w) * fr.lines[k0][s] + w * fr.lines[k0 + 1][s];
                    fr.halo[s] = (1.0f - w) * fr.halos[k0][s] + w * fr.halos[k0 + 1][s];
                }
            } else {
                fr.density = fr.lines[0];
                fr.halo = fr.halos[0];
            }
        }
        if (roiPost) {
            auto mask = [&](std::vector<float>& v) {
                for (std::size_t s = 0; s < v.size(); ++s) v[s] *= roiMask[s];
            };
            mask(fr.density);
            if (spots) {
                mask(fr.halo);
                for (auto& v : fr.lines) mask(v);
                for (auto& v : fr.halos) mask(v);
            }
        }
        return fr;
    };
    Frame first = composeFrameGrids(1);
    // Sparse output (spots): voxels whose line and halo are both ~0 stay inactive, in every grid
    // and frame (the union over the loop's frames, so the topology is the same in every file).
    std::vector<std::uint8_t> keep;
    const std::vector<std::uint8_t>* keepPtr = nullptr;
    if (spots) {
        keep.assign(domain.slotCount(), 0);
        auto mark = [&](const Frame& fr) {
            for (std::size_t s = 0; s < keep.size(); ++s)
                if (fr.density[s] > kSparseEpsilon || fr.halo[s] > kSparseEpsilon) keep[s] = 1;
        };
        mark(first);
        for (int f = 2; f <= frames; ++f) mark(composeFrameGrids(f));
        keepPtr = &keep;
    }

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
    densityMeta.insertMeta("lic_input", openvdb::StringMetadata(recipe.input.type));
    nlohmann::json spotsJson = nullptr;
    if (spots) {
        const std::string placement = recipe.input.surface ? "surface" : recipe.input.distribution;
        densityMeta.insertMeta("lic_spot_count", openvdb::Int64Metadata(openvdb::Int64(spotSet.centers.size())));
        densityMeta.insertMeta("lic_spot_placement", openvdb::StringMetadata(placement));
        densityMeta.insertMeta("lic_halo_scale", openvdb::FloatMetadata(float(recipe.input.haloScale)));
        spotsJson = {{"count", spotSet.centers.size()}, {"placement", placement},
                     {"spacing", recipe.input.spacing}, {"radii", recipe.input.radii},
                     {"halo_scale", recipe.input.haloScale}, {"line_peaks", linePeak}, {"halo_peaks", haloPeak}};
        if (recipe.width) {
            densityMeta.insertMeta("lic_width_scalar", openvdb::StringMetadata(recipe.width->scalar));
            densityMeta.insertMeta("lic_width_range",
                                   openvdb::Vec2DMetadata(openvdb::Vec2d(widthRange[0], widthRange[1])));
            spotsJson["width"] = {{"scalar", recipe.width->scalar}, {"range", widthRange},
                                  {"invert", recipe.width->invert}};
        }
    }
    auto makeDensity = [&](const std::vector<float>& values, int frame) {
        openvdb::FloatGrid::Ptr g = domain.makeGrid(values, "density", keepPtr);
        for (auto it = densityMeta.beginMeta(); it != densityMeta.endMeta(); ++it) g->insertMeta(it->first, *it->second);
        g->insertMeta("lic_frame", openvdb::Int32Metadata(frame));
        return g;
    };
    openvdb::GridPtrVec grids; // grids shared by every frame (density is added per frame)
    if (recipe.output.writeInput) {
        std::vector<float> input(domain.slotCount(), 0.0f);
        if (spots) {
            // The narrowest line level's spot texture at the voxel centres.
            const lic::SpotTexture<1> tex(spotSet, {recipe.input.radii[0]}, recipe.input.haloScale);
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, input.size()), [&](const auto& r) {
                float v[2];
                for (std::size_t s = r.begin(); s != r.end(); ++s) {
                    if (!domain.isActive(s)) continue;
                    tex.sample(domain.coordOf(s).asVec3d(), v);
                    input[s] = std::min(v[0], 1.0f);
                }
            });
        } else {
            for (std::size_t s = 0; s < input.size(); ++s)
                if (domain.isActive(s)) input[s] = noise->voxel(domain.coordOf(s));
        }
        grids.push_back(domain.makeGrid(input, "input", keepPtr));
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
        grids.push_back(domain.makeGrid<openvdb::Vec3SGrid>(tangent, "tangent", keepPtr));
    }
    nlohmann::json colorJson = nullptr;
    if (recipe.color) {
        const lic::Colormap cmap = loadColormap(recipe.color->colormap);
        // The field file's scalar grids were read with the field (loadField).
        const openvdb::FloatGrid::ConstPtr scalarGrid = scalarByName(recipe.color->scalar);
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
        grids.push_back(domain.makeGrid<openvdb::Vec3SGrid>(color, "color", keepPtr));
        grids.back()->setVectorType(openvdb::VEC_INVARIANT);
        grids.back()->insertMeta("licvdb_color_space", openvdb::StringMetadata("scene-linear Rec.709"));
        grids.push_back(domain.makeGrid(values, "scalar", keepPtr));
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
    OutputSet output; // frames and manifest, staged unseen and committed together (VdbIO.h)
    {
        for (int f = 1; f <= frames; ++f) {
            const Frame fr = f == 1 ? std::move(first) : composeFrameGrids(f);
            openvdb::GridPtrVec fileGrids{makeDensity(fr.density, f)};
            if (spots) {
                fileGrids.push_back(domain.makeGrid(fr.halo, "halo", keepPtr));
                if (recipe.output.writeSeries) {
                    for (int k = 0; k < K; ++k) {
                        fileGrids.push_back(domain.makeGrid(fr.lines[std::size_t(k)], "density_w" + std::to_string(k + 1), keepPtr));
                        fileGrids.push_back(domain.makeGrid(fr.halos[std::size_t(k)], "halo_w" + std::to_string(k + 1), keepPtr));
                    }
                }
            }
            fileGrids.insert(fileGrids.end(), grids.begin(), grids.end());
            if (recipe.output.half)
                for (const auto& g : fileGrids) g->setSaveFloatAsHalf(true);
            if (f == 1) firstGrids = fileGrids;
            output.addVdb(paths[std::size_t(f - 1)], fileGrids);
        }
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
    manifest["input"] = recipe.input.type;
    manifest["spots"] = spotsJson;
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
    for (const auto& p : paths) manifest["sha256"][fs::path(p).filename().string()] = output.sha256(p);
    output.addText(manifestPath(recipe.output.path), manifest.dump(2) + "\n");
    output.commit();
    const double tWrite = seconds(t3);

    const lic::LicStats& st = result.stats;
    return {
        {"output", recipe.output.path},
        {"files", paths},
        {"frames", frames},
        {"manifest", manifestPath(recipe.output.path)},
        {"field", {{"path", recipe.field.path}, {"grid", gridName}, {"format", loaded.format}, {"notes", loaded.notes},
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
        {"spots", spotsJson},
        {"density_active_voxels", firstGrids.front()->activeVoxelCount()},
        {"raw_mean", raw.mean},
        {"raw_stddev", raw.stddev},
        {"seconds", {{"read", tRead}, {"input", tInput}, {"convolve", st.seconds}, {"compose", tCompose},
                     {"write", tWrite}, {"total", seconds(t0)}}},
    };
}

} // namespace vdbexport

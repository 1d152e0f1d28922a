#include "Plan.h"

#include "vdbexport/bake/Outputs.h"
#include "vdbexport/io/VdbCheck.h"

#include "lic/util/Error.h"
#include "lic/engine/Engine.h"
#include "lic/engine/Kernels.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <thread>

namespace vdbexport::pipeline {

namespace fs = std::filesystem;

std::string outputDirectory(const std::string& out)
{
    const fs::path dir = fs::path(out).parent_path();
    return dir.empty() ? std::string(".") : dir.string();
}

namespace {

/// Refuse recipe features that later releases add, and combinations that mean nothing, rather
/// than silently ignoring them.
void checkSupported(const Recipe& r)
{
    const bool spots = r.input.type == "spots";
    try {
        (void)lic::chooseEngine(r.lic.engine, spots);
    } catch (const lic::InputError& e) {
        throw lic::InputError(std::string("lic.engine (--engine): ") + e.what());
    }
    checkEngineKeys(r);
    if (!spots && r.width) {
        throw lic::InputError("width needs spot input (input.type \"spots\", --input spots): line width "
                              "comes from the spot radii input.radii");
    }
    const bool series = r.output.writes(lic::OutputGrid::LevelLines);
    if (!spots && series) {
        throw lic::InputError("output.write_series (--write-series) needs spot input (input.type \"spots\")");
    }
    if (!spots && r.input.surface) {
        throw lic::InputError("input.surface places spots: it needs input.type \"spots\" (--input spots)");
    }
    if (!spots && !r.input.seeds.empty()) {
        throw lic::InputError("input.seeds (--seeds) places spots: it needs input.type \"spots\" (--input spots)");
    }
    if (spots && r.input.radii.size() > 4) {
        throw lic::InputError("input.radii has " + std::to_string(r.input.radii.size()) +
                              " radii; at most 4 width levels are supported");
    }
    if (spots && r.input.radii.size() > 1 && !r.width && !series) {
        throw lic::InputError("input.radii has " + std::to_string(r.input.radii.size()) +
                              " radii but nothing uses the wider levels: add a width scalar (width.scalar, "
                              "--width SCALAR) or output.write_series (--write-series), or give one radius");
    }
}

/// For a relative path, where it was looked for: a recipe's paths are relative to the working
/// directory, not to the recipe, which is easy to forget when running one from elsewhere.
std::string relativeToCwd(const fs::path& p)
{
    std::error_code ec;
    const fs::path cwd = fs::current_path(ec);
    if (p.is_absolute() || ec) return "";
    return "; relative paths (also a recipe's) are taken from the working directory " + cwd.string();
}

void checkOutputDirectory(const std::string& out)
{
    const fs::path dir = outputDirectory(out);
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) {
        throw lic::InputError("output directory \"" + dir.string() + "\" does not exist (for --out " + out + ")" +
                              relativeToCwd(dir));
    }
    if (fs::is_directory(out, ec)) {
        throw lic::InputError("output path \"" + out + "\" is a directory; expected a .vdb file name");
    }
}

/// A comet loop's brick holds frames · C sums per voxel (and as many outputs) on each thread:
/// refuse one that could not fit in this machine's memory before reading anything, rather than
/// failing (or being killed) on the first brick. Ripple loops and stills hold a few per voxel.
void checkLoopFits(const Plan& p)
{
    if (p.settings.comets <= 0) return;
    const double dim = double(lic::brickDim(p.settings));
    const int threads = p.recipe.threads > 0 ? p.recipe.threads : int(std::max(1u, std::thread::hardware_concurrency()));
    const double bytes = dim * dim * dim * double(p.rawChannels) * 2.0 * sizeof(float) * double(threads);
    const std::uint64_t limit = readMemoryLimitBytes();
    if (limit == 0 || bytes <= double(limit)) return;
    auto gib = [](double b) { return std::to_string(int(std::ceil(b / double(1u << 30)))); };
    throw lic::InputError("animation.frames: a loop of " + std::to_string(p.frames) + " frames of spots keeps " +
                          std::to_string(p.rawChannels) + " values per voxel of each " + std::to_string(int(dim)) +
                          "^3 brick being convolved: about " + gib(bytes) + " GiB on " + std::to_string(threads) +
                          " threads, more than this machine's memory (" + gib(double(limit)) +
                          " GiB); use fewer frames, smaller bricks (lic.brick) or fewer threads");
}

} // namespace

Plan makePlan(const Recipe& recipe)
{
    recipe.validate();
    recipe.validatePaths();
    checkSupported(recipe);
    // A missing relative field path says where it was looked for (the readers report the rest;
    // a '#' frame pattern is expanded by the sequence reader).
    std::error_code ec;
    if (recipe.field.path.find('#') == std::string::npos && !fs::exists(recipe.field.path, ec) &&
        !relativeToCwd(recipe.field.path).empty()) {
        throw lic::InputError("field file \"" + recipe.field.path + "\" not found" + relativeToCwd(recipe.field.path));
    }
    if (!recipe.input.seeds.empty() && !fs::exists(recipe.input.seeds, ec)) {
        throw lic::InputError("input.seeds: seeds file \"" + recipe.input.seeds + "\" not found; expected a .npy (N, 3) "
                              "or a text file of x y z lines (world units)" + relativeToCwd(recipe.input.seeds));
    }
    checkOutputDirectory(recipe.output.path);
    checkNotOverwritten(recipe, recipe.field.path, "the input field");

    Plan p{recipe, {}, 1, false, false, false, true, 1, 1, 1, {}, {}, 0.0};
    p.spots = recipe.input.type == "spots";
    lic::LicSettings& s = p.settings;
    s.engine = lic::chooseEngine(recipe.lic.engine, p.spots);
    s.integrator = lic::integratorFromString(recipe.lic.integrator);
    s.kernel = lic::kernelFromString(recipe.lic.kernel);
    s.decay = recipe.lic.decay;
    s.length = recipe.lic.length;
    s.step = recipe.lic.step;
    s.tolerance = recipe.lic.tolerance;
    s.minHits = recipe.lic.minHits;
    s.brick = recipe.lic.brick;
    s.threads = recipe.threads;
    p.frames = recipe.animation.frames;
    // Spot loops of the splat and fast engines carry travelling comets; every other loop (noise,
    // or spots with the naive engine) the ripple sums.
    if (p.frames > 1 && p.spots && s.engine != lic::EngineType::Naive) s.comets = p.frames;
    else s.ripple = p.frames > 1;
    s.validate();

    p.roiPre = recipe.roi && recipe.roi->mode == "pre";
    p.roiPost = recipe.roi && recipe.roi->mode == "post";
    p.stretch = recipe.output.contrast == "stretch";
    p.levels = int(recipe.input.radii.size());
    p.textureChannels = p.spots ? 2 * p.levels : 1;
    p.rawChannels = s.outputChannels(p.textureChannels);
    checkLoopFits(p);
    p.linePeak.assign(std::size_t(p.levels), 1.0);
    p.haloPeak.assign(std::size_t(p.levels), 1.0);
    if (p.spots && p.stretch) {
        for (int k = 0; k < p.levels; ++k) {
            const double r = recipe.input.radii[std::size_t(k)];
            p.linePeak[std::size_t(k)] = lic::spotPeak(s, r);
            p.haloPeak[std::size_t(k)] = lic::spotPeak(s, r * recipe.input.haloScale);
        }
    }
    if (p.spots)
        for (double r : recipe.input.radii) p.maxSpotRadius = std::max(p.maxSpotRadius, r * recipe.input.haloScale);
    return p;
}

} // namespace vdbexport::pipeline

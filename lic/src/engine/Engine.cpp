#include "lic/engine/Engine.h"

#include "lic/engine/Gather.h"
#include "lic/engine/Kernels.h"
#include "lic/engine/Splat.h"
#include "lic/util/Error.h"
#include "lic/util/Names.h"

#include <algorithm>
#include <cmath>

namespace lic {

// Gather engines' entry points, compiled in GatherNoise.cpp and GatherSpots.cpp.
template<typename Engine>
LicStats gatherNoiseBricks(const ConvolveJob& job, NoiseBrickSource& noise, const BrickSink& sink);
template<typename Engine>
LicStats gatherSpotBricks(const ConvolveJob& job, const SpotInput& spots, const BrickSink& sink);

namespace {

int gatherBrickDim(const LicSettings& settings)
{
    // Measured on the 128³ abc bake (docs/performance.md): 64 for kernels up to ~24 voxels;
    // longer kernels need larger bricks to keep the window tails (n samples past each end of a
    // line) a small part of each line. Powers of two, so power-of-two volumes split evenly.
    // Comet loops keep frames · C sums per voxel of a brick (and as many outputs): 64³, so that a
    // 24-frame loop's brick holds 0.1 GiB, not 0.8 (the figure-11 loop: 0.8 GiB peak instead of
    // 2.0, for 20 % more time).
    if (settings.comets > 0) return 64;
    return settings.length <= 24 ? 64 : 128;
}

/// Comet loops of the fast engine: how much farther its lines run past a brick (the train's
/// spacing, plus the sample a copy is shared with); 0 otherwise.
double gatherCometReach(const LicSettings& settings, double maxSpotRadius)
{
    return settings.comets > 0 ? cometSpacing(settings, maxSpotRadius) + 2.0 * settings.step : 0.0;
}

double gatherSpotReach(const LicSettings& settings, double maxSpotRadius)
{
    // A voxel's window (the ghost margin) meets the spot's largest halo, with its soft edge.
    return double(ghostMargin(settings)) + gatherCometReach(settings, maxSpotRadius) + (maxSpotRadius + 0.5) + 2.0;
}

double gatherFieldReach(const LicSettings& settings, bool spots, double maxSpotRadius, int stride)
{
    // The ghost margin (the last texture sample, with its rounding and footprint), one
    // integration step past the last sample (RK4 every `stride` samples, RK45 at most 2 voxels or
    // a step), a voxel of rounding; for spots, those whose weights a brick's texture reads (the
    // ROI pre-mask at their centres).
    const double integration = std::max({double(stride) * settings.step, 2.0, settings.step}) + 1.0;
    double out = double(ghostMargin(settings)) + integration;
    if (spots) out += gatherCometReach(settings, maxSpotRadius) + maxSpotRadius + 1.5;
    return out;
}

// The recipe's `lic` keys each engine reads (EngineInfo::keys). decay (exp kernel) and tolerance
// (rk45) are read only under those choices, by every engine alike.
constexpr std::string_view kNaiveKeys[] = {"kernel", "length", "step", "decay", "integrator", "tolerance", "brick"};
constexpr std::string_view kFastKeys[] = {"kernel", "length", "step", "decay", "integrator", "tolerance", "min_hits", "brick"};
constexpr std::string_view kSplatKeys[] = {"kernel", "length", "step", "decay", "integrator", "tolerance", "brick"};

// The engine table.
constexpr EngineInfo kEngines[] = {
    {EngineType::Naive, kEngineNames[0].name.data(), "every voxel traces its own streamline (the reference; slow)", kNaiveKeys,
     gatherBrickDim, gatherSpotReach, gatherFieldReach, gatherNoiseBricks<NaiveEngine>, gatherSpotBricks<NaiveEngine>},
    {EngineType::Fast, kEngineNames[1].name.data(), "fast-LIC: long streamlines deposit into every voxel they cross", kFastKeys,
     gatherBrickDim, gatherSpotReach, gatherFieldReach, gatherNoiseBricks<FastEngine>, gatherSpotBricks<FastEngine>},
    {EngineType::Splat, kEngineNames[2].name.data(), "spots only: one streamline per spot, its footprint splatted around it",
     kSplatKeys, splatBrickDim, splatSpotReach, splatFieldReach, nullptr, splatSpotBricks},
};

static_assert(std::size(kEngines) == std::size(kEngineNames));
static_assert(kEngines[0].type == kEngineNames[0].value && kEngines[1].type == kEngineNames[1].value
              && kEngines[2].type == kEngineNames[2].value);

/// Names of the engines that take noise (or spots), as "a or b".
std::string enginesTaking(bool spots)
{
    std::vector<EnumName<EngineType>> names;
    for (const EngineInfo& e : kEngines)
        if (spots ? e.spotBricks != nullptr : e.noiseBricks != nullptr) names.push_back({e.type, e.name});
    return listNames<EngineType>(names);
}

} // namespace

std::span<const EngineInfo> engines() { return kEngines; }

const EngineInfo& engineInfo(EngineType type)
{
    for (const EngineInfo& e : kEngines)
        if (e.type == type) return e;
    throw Error("engine " + std::to_string(int(type)) + " is not in the engine table");
}

const char* toString(EngineType e) { return engineInfo(e).name; }

EngineType engineFromString(const std::string& s) { return valueOf<EngineType>(engineNames(), s, "engine"); }

EngineType chooseEngine(const std::string& name, bool spots)
{
    if (name == "auto") return spots ? EngineType::Splat : EngineType::Fast;
    const EngineType type = engineFromString(name);
    const EngineInfo& e = engineInfo(type);
    if (spots ? e.spotBricks == nullptr : e.noiseBricks == nullptr) {
        throw InputError(std::string("engine \"") + e.name + "\" does not take " + (spots ? "spot" : "noise") +
                         " input; use " + enginesTaking(spots));
    }
    return type;
}

double SpotInput::maxRadius() const
{
    double r = 0.0;
    for (double rad : radii) r = std::max(r, rad * haloScale);
    return r;
}

int brickDim(const LicSettings& settings)
{
    return settings.brick > 0 ? settings.brick : engineInfo(settings.engine).defaultBrick(settings);
}

int ghostMargin(const LicSettings& settings)
{
    // A line leaves the brick at most half a voxel past its box (nearest-voxel rounding), then
    // traces n more samples of arc h: ≤ n·h index units on any axis. Two more voxels cover the
    // trilinear lookup and the binomial filter's footprint.
    const double tail = double(settings.halfSamples()) * settings.step;
    return int(std::ceil(tail + 0.5)) + 2;
}

double spotReach(const LicSettings& settings, double maxSpotRadius)
{
    return engineInfo(settings.engine).spotReach(settings, maxSpotRadius);
}

double fieldReach(const LicSettings& settings, bool spots, double maxSpotRadius, int stride)
{
    return engineInfo(settings.engine).fieldReach(settings, spots, maxSpotRadius, stride);
}

LicStats convolveNoiseBricks(const ConvolveJob& job, NoiseBrickSource& noise, const BrickSink& sink)
{
    job.settings.validate();
    const EngineInfo& e = engineInfo(job.settings.engine);
    if (!e.noiseBricks) {
        throw InputError(std::string("engine \"") + e.name + "\" does not take noise input; use " + enginesTaking(false));
    }
    const ThreadLimit limit(job.settings.threads);
    return e.noiseBricks(job, noise, sink);
}

LicStats convolveSpotBricks(const ConvolveJob& job, const SpotInput& spots, const BrickSink& sink)
{
    job.settings.validate();
    if (spots.radii.empty() || spots.radii.size() > 4) {
        throw InputError("input.radii has " + std::to_string(spots.radii.size()) +
                         " radii; between 1 and 4 width levels are supported");
    }
    const EngineInfo& e = engineInfo(job.settings.engine);
    if (!e.spotBricks) {
        throw InputError(std::string("engine \"") + e.name + "\" does not take spot input; use " + enginesTaking(true));
    }
    const ThreadLimit limit(job.settings.threads);
    return e.spotBricks(job, spots, sink);
}

LicResult convolveSpots(const VelocityField& field, const OutputDomain& domain, const SpotSet& spots,
                        const std::vector<double>& radii, double haloScale, const LicSettings& settings,
                        Progress& progress)
{
    settings.validate();
    const BrickLayout layout(domain, brickDim(settings));
    LicResult result;
    result.channels.assign(std::size_t(settings.outputChannels(2 * int(radii.size()))),
                           std::vector<float>(domain.slotCount(), 0.0f));
    result.stats = convolveSpotBricks({field, domain, layout, settings, progress}, {spots, radii, haloScale},
                                      [&](const BrickChannels& bc) { detail::copyBrick(bc, result.channels); });
    return result;
}

namespace detail {

void copyBrick(const BrickChannels& bc, std::vector<std::vector<float>>& channels)
{
    for (std::size_t i = 0; i < bc.brick->blocks.size(); ++i) {
        if (bc.blockTouched && !bc.blockTouched[i]) continue;
        const std::size_t slot0 = std::size_t(bc.brick->blocks[i]) * OutputDomain::kBlockVoxels;
        for (int c = 0; c < bc.channels; ++c)
            std::copy_n(bc.block(i, c), OutputDomain::kBlockVoxels,
                        channels[std::size_t(c)].begin() + std::ptrdiff_t(slot0));
    }
}

} // namespace detail
} // namespace lic

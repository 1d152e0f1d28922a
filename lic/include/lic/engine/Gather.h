// Gather engines: each output voxel's value is gathered from an input texture sampled along
// streamlines (naive: the voxel's own; fast: long lines that deposit into every voxel they
// cross). They run on the brick driver with any texture.
//
// The engine concept (NaiveEngine, FastEngine): kType, kStage (progress stage name),
// kReportsProgress (the engine advances progress itself), a per-thread Scratch, and
//     template<typename Texture, bool Ripple>
//     static void brick(field, domain, brick, texture, settings, scratch, out, stats, progress);
// that fills `out` with, for each of the brick's blocks in order, K runs of 512 floats
// (K = C, or 3C + 2 with Ripple) and adds its counters to `stats`.
//
// The texture concept (NoiseTexture, SpotTexture, ConstantTexture): kChannels, and
// sample(p, out) / sampleGradient(p, out, grad) at OUTPUT-index positions.
#pragma once

#include "lic/engine/Driver.h"
#include "lic/engine/Engine.h"
#include "lic/engine/Fast.h"
#include "lic/engine/Naive.h"
#include "lic/engine/Settings.h"
#include "lic/util/Error.h"
#include "lic/util/Parallel.h"

#include <chrono>
#include <string>
#include <type_traits>
#include <vector>

namespace lic {

/// Every gather engine: convolveBricks() dispatches on settings.engine among these.
template<typename... Engines>
struct EngineList
{
};
using GatherEngines = EngineList<NaiveEngine, FastEngine>;

/// Convolve every brick of `layout` with the gather engine `Engine`. `textureFor(brick)` returns
/// the input texture for that brick: the same texture for every brick, or one made for the brick
/// and its ghost margin (NoiseBrickSource). `sink(const BrickChannels&)` receives each finished
/// brick (see BrickSink). Deterministic: each brick's channels are bit-identical for any thread
/// count. Settings are not validated here (see convolveBricks()).
/// @throw lic::Cancelled if `progress` interrupts.
template<typename Engine, typename TextureFor, typename Sink>
LicStats gatherBricks(const VelocityField& field, const OutputDomain& domain, const BrickLayout& layout,
                      TextureFor&& textureFor, const LicSettings& settings, Progress& progress, Sink&& sink)
{
    using Texture = std::remove_cvref_t<decltype(textureFor(std::declval<const Brick&>()))>;
    const int K = settings.outputChannels(Texture::kChannels);
    struct Worker
    {
        typename Engine::Scratch scratch;
        ScratchVector<float> out;
        LicStats stats;
    };
    const auto start = std::chrono::steady_clock::now();
    progress.begin(Engine::kStage, domain.activeVoxelCount());
    LicStats stats = detail::forEachBrick<Worker>(
        layout, layout.positions(), progress, !Engine::kReportsProgress, [&](std::size_t, const Brick& brick, Worker& w) {
            const Texture& texture = textureFor(brick);
            if (settings.ripple) {
                Engine::template brick<Texture, true>(field, domain, brick, texture, settings, w.scratch, w.out, w.stats,
                                                      progress);
            } else {
                Engine::template brick<Texture, false>(field, domain, brick, texture, settings, w.scratch, w.out,
                                                       w.stats, progress);
            }
            sink(BrickChannels{brick.id, &brick, K, w.out.data(), nullptr});
        });
    progress.end();
    stats.voxels = domain.activeVoxelCount();
    stats.bricks = layout.size(); // convolved here (a subset's share in a distributed bake)
    stats.brickDim = layout.dim();
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
}

namespace detail {
template<typename TextureFor, typename Sink, typename... Engines>
LicStats dispatchGather(EngineList<Engines...>, const VelocityField& field, const OutputDomain& domain,
                        const BrickLayout& layout, TextureFor&& textureFor, const LicSettings& settings,
                        Progress& progress, Sink&& sink)
{
    LicStats stats;
    const bool ran = ((settings.engine == Engines::kType
                           ? (stats = gatherBricks<Engines>(field, domain, layout, textureFor, settings, progress, sink),
                              true)
                           : false) ||
                      ...);
    if (!ran) {
        throw InputError(std::string("engine \"") + toString(settings.engine) +
                         "\" does not sample a texture along streamlines: it takes spot input only "
                         "(input.type \"spots\"); use engine fast or naive for noise");
    }
    return stats;
}
} // namespace detail

/// Convolve every brick of `layout` with the gather engine settings.engine names (naive or
/// fast), on at most settings.threads threads; see gatherBricks().
/// @throw lic::InputError for invalid settings or an engine that is not a gather engine;
///        lic::Cancelled if `progress` interrupts.
template<typename TextureFor, typename Sink>
LicStats convolveBricks(const VelocityField& field, const OutputDomain& domain, const BrickLayout& layout,
                        TextureFor&& textureFor, const LicSettings& settings, Progress& progress, Sink&& sink)
{
    settings.validate();
    const ThreadLimit limit(settings.threads);
    return detail::dispatchGather(GatherEngines{}, field, domain, layout, std::forward<TextureFor>(textureFor), settings,
                                  progress, std::forward<Sink>(sink));
}

/// Convolve `texture` along the streamlines of `field` for every active voxel of `domain`, into
/// one float per output slot and channel (see OutputDomain). Bricks as convolveBricks() with the
/// same texture everywhere; for tests and small volumes (a bake streams bricks instead).
/// @throw lic::InputError for invalid settings; lic::Cancelled if `progress` interrupts.
template<typename Texture>
LicResult convolve(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress = nullProgress())
{
    settings.validate();
    const BrickLayout layout(domain, brickDim(settings));
    LicResult result;
    result.channels.assign(std::size_t(settings.outputChannels(Texture::kChannels)),
                           std::vector<float>(domain.slotCount(), 0.0f));
    result.stats = convolveBricks(
        field, domain, layout, [&](const Brick&) -> const Texture& { return texture; }, settings, progress,
        [&](const BrickChannels& bc) { detail::copyBrick(bc, result.channels); });
    return result;
}

} // namespace lic

// Line integral convolution engines: settings, results and the entry point.
#pragma once

#include "lic/engine/Bricks.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"
#include "lic/util/Parallel.h"
#include "lic/util/Progress.h"
#include "lic/engine/Streamline.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <chrono>
#include <functional>
#include <type_traits>

#include <cstdint>
#include <string>
#include <vector>

namespace lic {

enum class EngineType {
    Naive, ///< every voxel gathers along its own streamline (the reference)
    Fast,  ///< Stalling–Hege fast-LIC: long streamlines deposit into every voxel they cross
    Splat  ///< spots only: one streamline per spot, its footprint deposited around it (engine/Splat.h)
};
const char* toString(EngineType);
/// @throw lic::InputError for names other than "naive", "fast" and "splat".
EngineType engineFromString(const std::string&);

enum class KernelType {
    Box, ///< uniform weights over n samples each way
    Exp  ///< oriented: weights c^k over the n samples downstream (seed §7); bright heads point downstream
};
const char* toString(KernelType);
/// @throw lic::InputError for names other than "box" and "exp".
KernelType kernelFromString(const std::string&);

/// What to convolve and how. Lengths are in OUTPUT VOXELS (the smallest edge of an output voxel).
struct LicSettings
{
    EngineType engine = EngineType::Fast;
    Integrator integrator = Integrator::RK4;
    KernelType kernel = KernelType::Box;
    double decay = 0.9;      ///< exp kernel: weight ratio c of consecutive samples, in (0, 1)
    /// Also produce the ripple sums a cyclic animation is composed from (either kernel; see
    /// Animation.h). The result then has 3·C + 2 channels.
    bool ripple = false;
    double length = 20.0;    ///< kernel half-length, one direction (> 0)
    double step = 0.5;       ///< arc length between samples (> 0, ≤ length)
    double tolerance = 1e-3; ///< RK45 local error per step
    int minHits = 2;         ///< fast: a voxel with fewer deposits seeds its own streamline
    int threads = 0;         ///< worker threads, 0 = all cores
    /// fast: a streamline stops after this many consecutive samples in voxels that were
    /// already covered (plus the kernel half-length it needs to finish its window).
    int coveredRun = 64;
    /// fast: longest streamline per direction in output voxels; 0 = automatic (see engine/Fast.h).
    double maxStreamline = 0.0;
    /// Brick edge in output voxels (a multiple of 8); 0 = defaultBrickDim(). The output depends
    /// on it (bricks seed their own streamlines), never on the thread count.
    int brick = 0;
    /// fast: samples per RK4 step (the integration step is stride · step; the samples in between
    /// are interpolated); 0 = automatic (see detail::integrationStride).
    int stride = 0;

    /// Samples per direction of the kernel: round(length / step), at least 1.
    int halfSamples() const;
    /// @throw lic::InputError naming the first out-of-range parameter.
    void validate() const;
};

/// Counters of one convolution, identical for any thread count.
struct LicStats
{
    std::uint64_t voxels = 0;      ///< active output voxels
    std::uint64_t streamlines = 0; ///< streamlines traced (both directions count as one)
    std::uint64_t samples = 0;     ///< integration samples taken (seed points included)
    std::uint64_t deposits = 0;    ///< fast: values deposited into voxels
    std::uint64_t bricks = 0;      ///< bricks convolved
    int brickDim = 0;              ///< brick edge, output voxels
    double seconds = 0.0;          ///< wall-clock time of the convolution

    double samplesPerVoxel() const { return voxels ? double(samples) / double(voxels) : 0.0; }
};

/// Result: one float per output slot (see OutputDomain) and channel; inactive slots are 0.
struct LicResult
{
    std::vector<std::vector<float>> channels;
    LicStats stats;
};

/// One finished brick, as the engines hand it to a bake's sink: for each of `brick->blocks` (in
/// order) `channels` runs of 512 floats in leaf-offset order; inactive voxels hold 0.
struct BrickChannels
{
    std::size_t index = 0;          ///< the brick's id (its number in the whole domain's layout)
    const Brick* brick = nullptr;
    int channels = 0;
    const float* values = nullptr;
    /// Splat: per block, 0 when no spot reached it (its values are then not set); null = all set.
    const std::uint8_t* blockTouched = nullptr;
    const float* block(std::size_t i, int c) const
    {
        return values + (i * std::size_t(channels) + std::size_t(c)) * OutputDomain::kBlockVoxels;
    }
};

/// A bake's receiver of finished bricks (see convolveBricks).
using BrickSink = std::function<void(const BrickChannels&)>;

/// Convolve every brick of `layout`, in parallel (one brick per task; within a brick one thread).
/// `textureFor(brick)` returns the input texture for that brick (see NoiseTexture for the concept:
/// kChannels, sample, sampleGradient; output-index positions): the same texture for every brick,
/// or one made for the brick and its ghost margin. `sink(const BrickChannels&)` receives each
/// finished brick from the worker thread that made it; it must be thread-safe, and its result
/// must not depend on the order bricks arrive in. Neither may run TBB parallel work of its own
/// that could pick up another brick (each brick runs isolated, so nested work is safe but
/// serial is cheaper). Deterministic: each brick's channels are bit-identical for any thread count.
/// @throw lic::InputError for invalid settings; lic::Cancelled if `progress` interrupts.
template<typename TextureFor, typename Sink>
LicStats convolveBricks(const VelocityField& field, const OutputDomain& domain, const BrickLayout& layout,
                        TextureFor&& textureFor, const LicSettings& settings, Progress& progress, Sink&& sink);

/// Convolve `texture` along the streamlines of `field` for every active voxel of `domain`, into
/// one float per output slot and channel (see OutputDomain). Bricks as convolveBricks() with the
/// same texture everywhere; for tests and small volumes (a bake streams bricks instead).
/// @throw lic::InputError for invalid settings; lic::Cancelled if `progress` interrupts.
template<typename Texture>
LicResult convolve(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress = nullProgress());

namespace detail {
/// Ripple period in samples (cyclic animation): one ripple per kernel window, the 2n+1 samples of
/// a box window or the n+1 of an exp one (downstream only). See Animation.h and docs/technique.md §8.
int ripplePeriod(const LicSettings& settings);
/// Ripple phase step per sample: one period over ripplePeriod() samples.
inline double rippleStep(const LicSettings& settings) { return 2.0 * 3.14159265358979323846 / double(ripplePeriod(settings)); }

/// Kernel-weighted window sums along one streamline of N samples with W values each (row-major
/// `vals`): `win` (N × W) gets each sample's weighted sum, `norm` (N) its total weight.
/// Box: samples i−n … i+n, clamped to the line. Exp: Σ_{k=0..n} c^k v_{i+k}, clamped, from the
/// backward recurrence E_i = v_i + c·E_{i+1}, sum_i = E_i − c^{n+1}·E_{i+n+1}: it only ever
/// multiplies by c < 1, so it does not drift however long the line (the forward recurrence of
/// the seed paper divides by c and does).
void windowSums(KernelType kernel, double decay, int n, std::size_t N, int W, const double* vals,
                double* win, double* norm, std::vector<double>& scratch);
/// World-space tracing parameters for a domain and settings; `maxSamples` = the kernel's.
TraceSettings traceSettings(const VelocityField& field, const OutputDomain& domain,
                            const LicSettings& settings);
/// Samples per RK4 step of the fast engine: settings.stride, or automatically as many as fit in
/// about one field voxel (see docs/performance.md for the accuracy this keeps).
int integrationStride(const OutputDomain& domain, const LicSettings& settings);
/// The brick edge of these settings: settings.brick, or defaultBrickDim().
inline int brickDim(const LicSettings& settings) { return settings.brick > 0 ? settings.brick : defaultBrickDim(settings); }
} // namespace detail

} // namespace lic

#include "lic/engine/Fast.h"
#include "lic/engine/Naive.h"

namespace lic {

namespace detail {
/// Per-thread state of the brick driver.
struct BrickWorker
{
    FastScratch fast;
    BrickIndex index;
    std::vector<float> out;
    LicStats stats;
};
} // namespace detail

template<typename TextureFor, typename Sink>
LicStats convolveBricks(const VelocityField& field, const OutputDomain& domain, const BrickLayout& layout,
                        TextureFor&& textureFor, const LicSettings& settings, Progress& progress, Sink&& sink)
{
    using Texture = std::remove_cvref_t<decltype(textureFor(std::declval<const Brick&>()))>;
    constexpr int C = Texture::kChannels;
    settings.validate();
    if (settings.engine == EngineType::Splat) {
        throw InputError("engine \"splat\" deposits spot footprints: it needs spot input (input.type \"spots\"); "
                         "use engine fast or naive for noise");
    }
    const auto start = std::chrono::steady_clock::now();
    const bool fast = settings.engine == EngineType::Fast;
    const int K = settings.ripple ? 3 * C + 2 : C;
    tbb::enumerable_thread_specific<detail::BrickWorker> workers;

    auto runBrick = [&](std::size_t i) {
        detail::BrickWorker& w = workers.local();
        const Brick& brick = layout[i];
        const Texture& texture = textureFor(brick);
        if (fast) {
            w.index = BrickIndex(domain, brick, layout.dim());
            if (settings.ripple) fastLicBrick<Texture, true>(field, domain, brick, w.index, texture, settings, w.fast, w.out, w.stats);
            else fastLicBrick<Texture, false>(field, domain, brick, w.index, texture, settings, w.fast, w.out, w.stats);
        } else {
            if (settings.ripple) naiveLicBrick<Texture, true>(field, domain, brick, texture, settings, w.out, w.stats, progress);
            else naiveLicBrick<Texture, false>(field, domain, brick, texture, settings, w.out, w.stats, progress);
        }
        sink(BrickChannels{brick.id, &brick, K, w.out.data(), nullptr});
    };

    progress.begin(fast ? "fast LIC" : "naive LIC", domain.activeVoxelCount());
    detail::runWithThreads(settings.threads, [&] {
        tbb::parallel_for(
            tbb::blocked_range<std::size_t>(0, layout.size(), 1),
            [&](const tbb::blocked_range<std::size_t>& r) {
                for (std::size_t i = r.begin(); i != r.end(); ++i) {
                    detail::checkCancel(progress);
                    // Isolated: a worker waiting inside nested parallel work cannot pick up
                    // another brick and clobber its own per-thread buffers.
                    tbb::this_task_arena::isolate([&] { runBrick(i); });
                    if (fast) progress.advance(layout[i].activeVoxels); // naive reports per block
                }
            },
            tbb::simple_partitioner());
    });
    progress.end();

    LicStats stats;
    for (const detail::BrickWorker& w : workers) {
        stats.samples += w.stats.samples;
        stats.deposits += w.stats.deposits;
        stats.streamlines += w.stats.streamlines;
    }
    stats.voxels = domain.activeVoxelCount();
    stats.bricks = layout.size(); // convolved here (a subset's share in a distributed bake)
    stats.brickDim = layout.dim();
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
}

template<typename Texture>
LicResult convolve(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress)
{
    settings.validate();
    const BrickLayout layout(domain, detail::brickDim(settings));
    const int K = settings.ripple ? 3 * Texture::kChannels + 2 : Texture::kChannels;
    LicResult result;
    result.channels.assign(std::size_t(K), std::vector<float>(domain.slotCount(), 0.0f));
    result.stats = convolveBricks(
        field, domain, layout, [&](const Brick&) -> const Texture& { return texture; }, settings, progress,
        [&](const BrickChannels& bc) {
            for (std::size_t i = 0; i < bc.brick->blocks.size(); ++i) {
                if (bc.blockTouched && !bc.blockTouched[i]) continue;
                const std::size_t slot0 = std::size_t(bc.brick->blocks[i]) * OutputDomain::kBlockVoxels;
                for (int c = 0; c < K; ++c)
                    std::copy_n(bc.block(i, c), OutputDomain::kBlockVoxels, result.channels[std::size_t(c)].begin() + std::ptrdiff_t(slot0));
            }
        });
    return result;
}

} // namespace lic

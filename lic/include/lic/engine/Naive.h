// The reference LIC engine: every output voxel integrates its own streamline and averages the
// input texture along it. Simple, exact, and O(kernel length) per voxel; bricked like fast-LIC
// only so that both run on the one brick driver (engine/Gather.h).
#pragma once

#include "lic/engine/Kernels.h"
#include "lic/engine/Settings.h"
#include "lic/engine/Streamline.h"
#include "lic/field/Bricks.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"
#include "lic/util/Buffer.h"
#include "lic/util/Parallel.h"
#include "lic/util/Progress.h"

#include <openvdb/math/Vec3.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

namespace lic {

/// The naive gather engine (see engine/Gather.h for the engine concept).
struct NaiveEngine
{
    static constexpr EngineType kType = EngineType::Naive;
    static constexpr const char* kStage = "naive LIC";
    /// Naive is slow: it reports progress per block, not per brick.
    static constexpr bool kReportsProgress = true;
    struct Scratch
    {
    };

    /// Naive LIC of one brick: for every active voxel x of the brick,
    /// I(x) = Σ_{i=−n..n} T(σ_x(i·h)) / (number of samples inside the domain), where σ_x is the
    /// arc-length streamline through the centre of x and n = settings.halfSamples() (exp kernel:
    /// weights c^k over the n samples downstream). `out` gets, for each of the brick's blocks in
    /// order, K runs of 512 floats (K = C, or 3C + 2 with Ripple), as FastEngine::brick() does.
    template<typename Texture, bool Ripple>
    static void brick(const VelocityField& field, const OutputDomain& domain, const Brick& brick,
                      const Texture& texture, const LicSettings& settings, Scratch&, ScratchVector<float>& out,
                      LicStats& stats, Progress& progress);

private:
    /// One voxel's channels (K runs of 512 floats apart from `dst`); returns the samples taken.
    template<typename Texture, bool Ripple>
    static std::size_t voxel(const VelocityField& field, const OutputDomain& domain, const openvdb::Coord& ijk,
                             const Texture& texture, const LicSettings& settings, const TraceSettings& ts,
                             std::vector<openvdb::Vec3d>& line, float* dst);
};

template<typename Texture, bool Ripple>
void NaiveEngine::brick(const VelocityField& field, const OutputDomain& domain, const Brick& brick,
                        const Texture& texture, const LicSettings& settings, Scratch&, ScratchVector<float>& out,
                        LicStats& stats, Progress& progress)
{
    constexpr int C = Texture::kChannels;
    constexpr int K = Ripple ? 3 * C + 2 : C;
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    const TraceSettings ts = detail::traceSettings(field, domain, settings);
    out.assign(brick.blocks.size() * std::size_t(K) * V, 0.0f);
    // Every voxel is independent of the others: the brick's blocks run in parallel (any order
    // gives the same values), so naive keeps both cores busy even on a one-brick volume.
    std::atomic<std::uint64_t> samplesTotal{0};
    tbb::enumerable_thread_specific<std::vector<openvdb::Vec3d>> lines;
    tbb::parallel_for(std::size_t(0), brick.blocks.size(), [&](std::size_t bi) {
        detail::checkCancel(progress);
        std::vector<openvdb::Vec3d>& line = lines.local();
        std::uint64_t samples = 0;
        const std::uint32_t b = brick.blocks[bi];
        float* dst = out.data() + bi * std::size_t(K) * V;
        const auto& mask = domain.blockMask(b);
        for (auto on = mask.beginOn(); on; ++on) {
            const std::size_t off = on.pos();
            samples += voxel<Texture, Ripple>(field, domain, domain.coordOf(std::size_t(b) * V + off), texture, settings,
                                              ts, line, dst + off);
        }
        samplesTotal += samples;
        progress.advance(mask.countOn());
    });
    stats.samples += samplesTotal.load();
    stats.streamlines += brick.activeVoxels;
}

template<typename Texture, bool Ripple>
std::size_t NaiveEngine::voxel(const VelocityField& field, const OutputDomain& domain, const openvdb::Coord& ijk,
                               const Texture& texture, const LicSettings& settings, const TraceSettings& ts,
                               std::vector<openvdb::Vec3d>& line, float* dst)
{
    constexpr int C = Texture::kChannels;
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    const double theta = detail::rippleStep(settings);
    const bool oriented = settings.kernel == KernelType::Exp;
    const openvdb::Vec3d seed = domain.worldOf(ijk);
    line.clear();
    traceStreamline(field, seed, +1.0, ts, line);
    const std::size_t forward = line.size();
    if (!oriented) traceStreamline(field, seed, -1.0, ts, line);
    // Box: equal weights both ways. Exp: weight c^k at the k-th sample downstream.
    double sum[C] = {}, weight = 1.0, total = 0.0;
    float v[C];
    texture.sample(ijk.asVec3d(), v);
    for (int c = 0; c < C; ++c) sum[c] += v[c];
    total += 1.0;
    // Ripple sums (cyclic animation): Σ T e^{iθk} and Σ e^{iθk}, k the signed sample offset
    // (downstream positive).
    double zr[C] = {}, zi[C] = {}, nr = 0.0, ni = 0.0;
    if constexpr (Ripple) {
        for (int c = 0; c < C; ++c) zr[c] += v[c];
        nr += 1.0;
    }
    for (std::size_t q = 0; q < line.size(); ++q) {
        weight = oriented ? weight * settings.decay : 1.0;
        texture.sample(domain.map().toIndex(line[q]), v);
        for (int c = 0; c < C; ++c) sum[c] += weight * v[c];
        total += weight;
        if constexpr (Ripple) {
            const double k = q < forward ? double(q + 1) : -double(q - forward + 1);
            const double cs = std::cos(theta * k), sn = std::sin(theta * k);
            for (int c = 0; c < C; ++c) {
                zr[c] += weight * v[c] * cs;
                zi[c] += weight * v[c] * sn;
            }
            nr += weight * cs;
            ni += weight * sn;
        }
    }
    for (int c = 0; c < C; ++c) dst[std::size_t(c) * V] = float(sum[c] / total);
    if constexpr (Ripple) {
        for (int c = 0; c < C; ++c) {
            dst[std::size_t(C + c) * V] = float(zr[c] / total);
            dst[std::size_t(2 * C + c) * V] = float(zi[c] / total);
        }
        dst[std::size_t(3 * C) * V] = float(nr / total);
        dst[std::size_t(3 * C + 1) * V] = float(ni / total);
    }
    return line.size() + 1;
}

} // namespace lic

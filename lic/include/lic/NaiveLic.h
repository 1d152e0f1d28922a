// The reference LIC engine: every output voxel integrates its own streamline and averages the
// input texture along it (box kernel). Simple, exact, and O(kernel length) per voxel.
#pragma once

#include "lic/Error.h"
#include "lic/Parallel.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>

namespace lic {

struct LicSettings;
struct LicResult;


/// Naive LIC: I(x) = Σ_{i=−n..n} T(σ_x(i·h)) / (number of samples inside the domain), where σ_x is
/// the arc-length streamline through the centre of voxel x and n = settings.halfSamples().
template<typename Texture>
LicResult naiveLic(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress)
{
    constexpr int C = Texture::kChannels;
    const auto start = std::chrono::steady_clock::now();
    const TraceSettings ts = detail::traceSettings(field, domain, settings);
    LicResult result;
    result.channels.assign(C, std::vector<float>(domain.slotCount(), 0.0f));
    std::atomic<std::uint64_t> samples{0};
    const bool oriented = settings.kernel == KernelType::Exp;

    progress.begin("naive LIC", domain.activeVoxelCount());
    detail::runWithThreads(settings.threads, [&] {
        tbb::enumerable_thread_specific<std::vector<openvdb::Vec3d>> tlsLine;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, domain.blockCount()), [&](const auto& r) {
            std::vector<openvdb::Vec3d>& line = tlsLine.local();
            std::uint64_t localSamples = 0;
            for (std::size_t b = r.begin(); b != r.end(); ++b) {
                detail::checkCancel(progress);
                const auto& mask = domain.blockMask(b);
                for (std::size_t off = mask._Find_first(); off < mask.size(); off = mask._Find_next(off)) {
                    const std::size_t slot = b * OutputDomain::kBlockVoxels + off;
                    const openvdb::Coord ijk = domain.coordOf(slot);
                    const openvdb::Vec3d seed = domain.worldOf(ijk);
                    line.clear();
                    traceStreamline(field, seed, +1.0, ts, line);
                    if (!oriented) traceStreamline(field, seed, -1.0, ts, line);
                    // Box: equal weights both ways. Exp: weight c^k at the k-th sample downstream.
                    double sum[C] = {}, weight = 1.0, total = 0.0;
                    float v[C];
                    texture.sample(ijk.asVec3d(), v);
                    for (int c = 0; c < C; ++c) sum[c] += v[c];
                    total += 1.0;
                    for (const openvdb::Vec3d& p : line) {
                        weight = oriented ? weight * settings.decay : 1.0;
                        texture.sample(domain.map().toIndex(p), v);
                        for (int c = 0; c < C; ++c) sum[c] += weight * v[c];
                        total += weight;
                    }
                    for (int c = 0; c < C; ++c) result.channels[c][slot] = float(sum[c] / total);
                    localSamples += line.size() + 1;
                }
                progress.advance(mask.count());
            }
            samples += localSamples;
        });
    });
    progress.end();

    result.stats.voxels = domain.activeVoxelCount();
    result.stats.streamlines = domain.activeVoxelCount();
    result.stats.samples = samples.load();
    result.stats.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
}

} // namespace lic

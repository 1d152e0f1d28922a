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
template<typename Texture, bool Ripple = false>
LicResult naiveLic(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress)
{
    constexpr int C = Texture::kChannels;
    constexpr int K = Ripple ? 3 * C + 2 : C; // output channels, as in fastLic()
    const double theta = detail::rippleStep(settings.halfSamples());
    const auto start = std::chrono::steady_clock::now();
    const TraceSettings ts = detail::traceSettings(field, domain, settings);
    LicResult result;
    result.channels.assign(K, std::vector<float>(domain.slotCount(), 0.0f));
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
                    const std::size_t forward = line.size();
                    if (!oriented) traceStreamline(field, seed, -1.0, ts, line);
                    // Box: equal weights both ways. Exp: weight c^k at the k-th sample downstream.
                    double sum[C] = {}, weight = 1.0, total = 0.0;
                    float v[C];
                    texture.sample(ijk.asVec3d(), v);
                    for (int c = 0; c < C; ++c) sum[c] += v[c];
                    total += 1.0;
                    // Ripple sums (cyclic animation): Σ T e^{iθk} and Σ e^{iθk}, k the signed
                    // sample offset (downstream positive).
                    double zr[C] = {}, zi[C] = {}, nr = 0.0, ni = 0.0;
                    if constexpr (Ripple) {
                        for (int c = 0; c < C; ++c) zr[c] += v[c];
                        nr += 1.0;
                    }
                    for (std::size_t q = 0; q < line.size(); ++q) {
                        const openvdb::Vec3d& p = line[q];
                        weight = oriented ? weight * settings.decay : 1.0;
                        texture.sample(domain.map().toIndex(p), v);
                        for (int c = 0; c < C; ++c) sum[c] += weight * v[c];
                        total += weight;
                        if constexpr (Ripple) {
                            const double k = q < forward ? double(q + 1) : -double(q - forward + 1);
                            const double cs = std::cos(theta * k), sn = std::sin(theta * k);
                            for (int c = 0; c < C; ++c) {
                                zr[c] += v[c] * cs;
                                zi[c] += v[c] * sn;
                            }
                            nr += cs;
                            ni += sn;
                        }
                    }
                    for (int c = 0; c < C; ++c) result.channels[c][slot] = float(sum[c] / total);
                    if constexpr (Ripple) {
                        for (int c = 0; c < C; ++c) {
                            result.channels[C + c][slot] = float(zr[c] / total);
                            result.channels[2 * C + c][slot] = float(zi[c] / total);
                        }
                        result.channels[3 * C][slot] = float(nr / total);
                        result.channels[3 * C + 1][slot] = float(ni / total);
                    }
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

// Fast-LIC (Stalling & Hege 1995) in 3D, parallel and deterministic.
//
// One long streamline is traced from a seed voxel; a box window slides along it (prefix sums
// make each window O(1)), and every sample point deposits its window average into the output
// voxel it lies in. Voxels are normalised by their hit count at the end. New seeds are taken
// only from voxels that no streamline has covered yet, so the cost per voxel is nearly
// independent of the kernel length.
//
// Determinism for any thread count: the volume is cut into tiles of 32³ output voxels. Work
// proceeds in rounds; in each round every tile with uncovered voxels seeds ONE streamline at its
// first uncovered voxel (scan order), all seeds trace in parallel, and deposits are accumulated
// as 32.32 fixed-point integers with atomic adds (integer addition is associative, so the order
// of deposits does not matter). The "covered" flags that steer seeding and early termination are
// updated only between rounds. Every decision therefore depends only on the state at the start of
// the round, never on thread timing.
#pragma once

#include "lic/Error.h"
#include "lic/Parallel.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>

namespace lic {

namespace detail {

/// Fixed-point scale of deposit weights: 2^30. A deposit adds round(w·2^30) to the voxel's
/// weight and round(value·w·2^30) to its sum; int64 holds ~2^33 full-weight deposits of 1.0.
constexpr double kWeightScale = 1073741824.0;
/// Deposit weight 1/(1 + k|δ|²)², δ = voxel centre − sample (output voxels): 1 at the centre,
/// 0.08 half a voxel away (close to exp(−|δ|²/0.1), without the exp).
constexpr double kDepositFalloff = 10.0;

/// The output voxels of one 32³ tile, in scan order.
struct FastTile
{
    std::vector<std::uint32_t> blocks; // block indices in the tile, ascending
    std::size_t cursor = 0;            // position in the tile's slot sequence
};

std::vector<FastTile> makeFastTiles(const OutputDomain& domain);



} // namespace detail

/// Fast-LIC with a box kernel of n = settings.halfSamples() samples each way. Gives the same
/// value as naiveLic() at every streamline's seed voxel, and window averages at points within
/// half a voxel of the centre elsewhere.
template<typename Texture, bool Ripple = false>
LicResult fastLic(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                  const LicSettings& settings, Progress& progress)
{
    using openvdb::Vec3d;
    constexpr int C = Texture::kChannels;
    // Output channels: the box average per texture channel; with Ripple (cyclic animation) also
    // the complex ripple sums Z/N per channel and the ripple weight sum NZ/N (see Animation.h).
    constexpr int K = Ripple ? 3 * C + 2 : C;
    const auto start = std::chrono::steady_clock::now();
    const int n = settings.halfSamples();
    const double theta = detail::rippleStep(n);
    TraceSettings ts = detail::traceSettings(field, domain, settings);
    // Long streamlines amortise the 2n samples each one spends filling its window.
    const double maxLen = settings.maxStreamline > 0 ? settings.maxStreamline
                                                     : std::max(8.0 * settings.length, 200.0);
    ts.maxSamples = std::max(2 * n + settings.coveredRun,
                             int(std::lround(maxLen / settings.step)));

    const std::size_t nSlots = domain.slotCount();
    // One accumulator per voxel, so a deposit touches one cache line.
    struct Acc
    {
        std::int64_t weight; // Σ deposit weights, fixed point
        std::int64_t sum[K]; // Σ weight · value, fixed point
        std::uint32_t hits;  // number of deposits
    };
    std::vector<Acc> acc(nSlots, Acc{});
    std::vector<std::uint8_t> covered(nSlots, 0);
    std::vector<detail::FastTile> tiles = detail::makeFastTiles(domain);

    struct Line
    {
        std::vector<Vec3d> fwd, bwd;              // world positions
        std::vector<std::int64_t> slotF, slotB;   // output slot per sample (−1 = none)
        std::vector<Vec3d> idxF, idxB;            // output-index position per sample
        std::vector<Vec3d> idx;                   // output-index positions, assembled
        std::vector<std::int64_t> slot;           // slots, assembled
        std::vector<double> vals, win, norm, scratch; // samples, window sums, kernel weights
        std::vector<std::int64_t> touched;        // slots deposited into this round
    };
    tbb::enumerable_thread_specific<Line> tls;
    std::atomic<std::uint64_t> samples{0}, deposits{0}, streamlines{0}, newlyCovered{0};
    std::vector<std::int64_t> seeds;
    seeds.reserve(tiles.size());
    const int minHits = settings.minHits;
    const int coveredRun = settings.coveredRun;

    // Trace one side; `slots` receives each sample's slot. Returns true when the side ended
    // naturally (boundary or critical point), i.e. its last windows are complete.
    auto traceSide = [&](const Vec3d& seedW, double sign, std::vector<Vec3d>& pts,
                         std::vector<std::int64_t>& slots, std::vector<Vec3d>& idx) {
        pts.clear();
        slots.clear();
        idx.clear();
        int run = 0, tail = -1;
        const StopReason why = traceStreamline(field, seedW, sign, ts, pts, [&](const Vec3d& p) {
            idx.push_back(domain.map().toIndex(p));
            const std::int64_t s = domain.slotOf(OutputDomain::nearestVoxel(idx.back()));
            slots.push_back(s);
            if (tail >= 0) return --tail > 0;
            run = (s < 0 || std::atomic_ref<std::uint8_t>(covered[std::size_t(s)])
                                .load(std::memory_order_relaxed))
                      ? run + 1
                      : 0;
            if (run >= coveredRun) tail = n; // finish the window, then stop
            return true;
        });
        return why == StopReason::Boundary || why == StopReason::ZeroVelocity;
    };

    auto traceAndDeposit = [&](std::int64_t seedSlot) {
        Line& L = tls.local();
        const openvdb::Coord ijk = domain.coordOf(std::size_t(seedSlot));
        const Vec3d seedW = domain.worldOf(ijk);
        const bool bwdNatural = traceSide(seedW, -1.0, L.bwd, L.slotB, L.idxB);
        const bool fwdNatural = traceSide(seedW, +1.0, L.fwd, L.slotF, L.idxF);
        const std::size_t B = L.bwd.size(), F = L.fwd.size(), N = B + 1 + F;

        L.idx.resize(N);
        L.slot.resize(N);
        for (std::size_t i = 0; i < B; ++i) {
            L.idx[i] = L.idxB[B - 1 - i];
            L.slot[i] = L.slotB[B - 1 - i];
        }
        L.idx[B] = ijk.asVec3d();
        L.slot[B] = seedSlot;
        for (std::size_t i = 0; i < F; ++i) {
            L.idx[B + 1 + i] = L.idxF[i];
            L.slot[B + 1 + i] = L.slotF[i];
        }
        // Per sample: C values, then 3·C gradient components (output-index units). With Ripple
        // the same again times cos θ_j and times sin θ_j, then cos θ_j and sin θ_j themselves.
        constexpr int P = 4 * C;
        constexpr int W = Ripple ? 3 * P + 2 : P;
        L.vals.resize(N * W);
        L.win.resize(N * W);
        L.norm.resize(N);
        float v[P];
        for (std::size_t i = 0; i < N; ++i) {
            texture.sampleGradient(L.idx[i], v, v + C);
            double* out = &L.vals[i * W];
            for (int c = 0; c < P; ++c) out[c] = v[c];
            if constexpr (Ripple) {
                const double cs = std::cos(theta * double(i)), sn = std::sin(theta * double(i));
                for (int c = 0; c < P; ++c) {
                    out[P + c] = v[c] * cs;
                    out[2 * P + c] = v[c] * sn;
                }
                out[3 * P] = cs;
                out[3 * P + 1] = sn;
            }
        }
        detail::windowSums(settings.kernel, settings.decay, n, N, W, L.vals.data(), L.win.data(),
                           L.norm.data(), L.scratch);
        // Samples whose window runs past an artificial end (length limit, early stop) are not
        // deposited; near a natural end the window is truncated exactly as in naiveLic(). The exp
        // kernel only looks downstream, so the upstream end never cuts a window.
        const bool oriented = settings.kernel == KernelType::Exp;
        const std::size_t lo = (bwdNatural || oriented) ? 0 : std::min(B, std::size_t(n));
        const std::size_t hi = fwdNatural ? N - 1 : std::max(B, N - 1 - std::size_t(n));
        std::uint64_t dep = 0;
        for (std::size_t i = lo; i <= hi; ++i) {
            const std::int64_t s = L.slot[i];
            if (s < 0) continue;
            const double inv = 1.0 / L.norm[i];
            // First-order correction from the sample point to the voxel centre: the window
            // average of the texture gradient applied to the offset δ (the streamline through the
            // centre is, to first order, this one shifted by δ). Deposits are weighted by
            // 1/(1 + 10|δ|²)², so passes near the centre dominate a voxel's average.
            const Vec3d off = OutputDomain::nearestVoxel(L.idx[i]).asVec3d() - L.idx[i];
            const double r2 = 1.0 + off.lengthSqr() * detail::kDepositFalloff;
            const double w = 1.0 / (r2 * r2);
            const std::int64_t wq = std::max<std::int64_t>(1, std::llround(w * detail::kWeightScale));
            const double* Wi = &L.win[i * W];
            double out[K];
            for (int c = 0; c < C; ++c) {
                const double* g = Wi + C + 3 * c;
                out[c] = (Wi[c] + g[0] * off[0] + g[1] * off[1] + g[2] * off[2]) * inv;
            }
            if constexpr (Ripple) {
                // Window sums relative to sample i: rotate Σ_j x_j e^{iθj} by e^{−iθi} (cos θ_i and
                // sin θ_i are stored with the sample).
                const double cs = L.vals[i * W + 3 * P], sn = L.vals[i * W + 3 * P + 1];
                const double* Rc = Wi + P;
                const double* Rs = Wi + 2 * P;
                auto re = [&](int k) { return Rc[k] * cs + Rs[k] * sn; };
                auto im = [&](int k) { return Rs[k] * cs - Rc[k] * sn; };
                for (int c = 0; c < C; ++c) {
                    const int g = C + 3 * c;
                    out[C + c] = (re(c) + re(g) * off[0] + re(g + 1) * off[1] + re(g + 2) * off[2]) * inv;
                    out[2 * C + c] = (im(c) + im(g) * off[0] + im(g + 1) * off[1] + im(g + 2) * off[2]) * inv;
                }
                const double nc = Wi[3 * P], ns = Wi[3 * P + 1];
                out[3 * C] = (nc * cs + ns * sn) * inv;
                out[3 * C + 1] = (ns * cs - nc * sn) * inv;
            }
            for (int k = 0; k < K; ++k) {
                std::atomic_ref<std::int64_t>(acc[std::size_t(s)].sum[k])
                    .fetch_add(std::llround(out[k] * double(wq)), std::memory_order_relaxed);
            }
            std::atomic_ref<std::int64_t>(acc[std::size_t(s)].weight).fetch_add(wq, std::memory_order_relaxed);
            std::atomic_ref<std::uint32_t>(acc[std::size_t(s)].hits).fetch_add(1, std::memory_order_relaxed);
            L.touched.push_back(s);
            ++dep;
        }
        samples += N;
        deposits += dep;
        ++streamlines;
    };

    progress.begin("fast LIC", domain.activeVoxelCount());
    int rounds = 0;
    detail::runWithThreads(settings.threads, [&] {
        for (;;) {
            detail::checkCancel(progress);
            // 1. Seeds: the next uncovered voxel of each tile in scan order (reads `covered`
            //    only). A voxel with fewer than minHits deposits when the scan reaches it seeds
            //    its own streamline, so min_hits > 1 trades time for more exact voxels.
            std::vector<std::int64_t> tileSeed(tiles.size(), -1);
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tiles.size()), [&](const auto& r) {
                for (std::size_t t = r.begin(); t != r.end(); ++t) {
                    detail::FastTile& tile = tiles[t];
                    const std::size_t total = tile.blocks.size() * OutputDomain::kBlockVoxels;
                    for (; tile.cursor < total; ++tile.cursor) {
                        const std::size_t b = tile.blocks[tile.cursor / OutputDomain::kBlockVoxels];
                        const std::size_t off = tile.cursor % OutputDomain::kBlockVoxels;
                        const std::size_t slot = b * OutputDomain::kBlockVoxels + off;
                        if (domain.blockMask(b).test(off) && !covered[slot]) {
                            tileSeed[t] = std::int64_t(slot);
                            ++tile.cursor; // each voxel seeds at most once
                            break;
                        }
                    }
                }
            });
            seeds.clear();
            for (std::int64_t s : tileSeed)
                if (s >= 0) seeds.push_back(s);
            if (seeds.empty()) break;
            ++rounds;

            // 2. Trace and deposit, all seeds in parallel.
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, seeds.size(), 1), [&](const auto& r) {
                for (std::size_t i = r.begin(); i != r.end(); ++i) traceAndDeposit(seeds[i]);
            });

            // 3. Publish coverage for the next round.
            for (Line& L : tls) {
                tbb::parallel_for(tbb::blocked_range<std::size_t>(0, L.touched.size()), [&](const auto& r) {
                    std::uint64_t fresh = 0;
                    for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const std::size_t s = std::size_t(L.touched[i]);
                        if (acc[s].hits < std::uint32_t(minHits)) continue;
                        std::uint8_t expected = 0;
                        if (std::atomic_ref<std::uint8_t>(covered[s]).compare_exchange_strong(expected, 1))
                            ++fresh;
                    }
                    newlyCovered += fresh;
                    progress.advance(fresh);
                });
                L.touched.clear();
            }
        }
    });
    progress.end();

    LicResult result;
    result.channels.assign(K, std::vector<float>(nSlots, 0.0f));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nSlots), [&](const auto& r) {
        for (std::size_t s = r.begin(); s != r.end(); ++s) {
            if (acc[s].hits == 0) continue;
            const double inv = 1.0 / double(acc[s].weight);
            for (int k = 0; k < K; ++k) result.channels[k][s] = float(double(acc[s].sum[k]) * inv);
        }
    });
    result.stats.voxels = domain.activeVoxelCount();
    result.stats.streamlines = streamlines.load();
    result.stats.samples = samples.load();
    result.stats.deposits = deposits.load();
    result.stats.rounds = rounds;
    result.stats.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
}

} // namespace lic

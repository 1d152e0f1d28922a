// Sparse spot input textures (seed §5, §6, §8): spot centres from four distributions, and the
// multi-channel texture of concentric smooth-edged spheres (line radii r_k and halo radii
// R_k = halo_scale·r_k) that one streamline trace convolves all at once.
//
// All positions are OUTPUT index space (one unit = one output voxel). Every placement is a pure
// function of (seed, parameters, box): no shared RNG stream, no dependence on thread count.
#pragma once

#include "lic/util/Error.h"
#include "lic/util/IndexMath.h"
#include "lic/util/Names.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace lic {

enum class SpotDistribution {
    Regular,  ///< cubic lattice of spacing d, centres at (i + ½)·d
    Random,   ///< uniform random, the lattice's expected count (box volume / d³)
    Jittered, ///< lattice point + per-axis offset uniform in ±jitter·d/2 (jitter 1 = anywhere in its cell)
    Poisson   ///< approximate Poisson-disk (Bridson's dart throwing), minimum distance kPoissonRadius·d
};
/// The distributions' names (a recipe's allowed values).
inline constexpr EnumName<SpotDistribution> kDistributionNames[] = {{SpotDistribution::Regular, "regular"},
                                                             {SpotDistribution::Random, "random"},
                                                             {SpotDistribution::Jittered, "jittered"},
                                                             {SpotDistribution::Poisson, "poisson"}};
inline std::span<const EnumName<SpotDistribution>> spotDistributionNames() { return kDistributionNames; }
const char* toString(SpotDistribution);
/// @throw lic::InputError for names other than regular, random, jittered, poisson.
SpotDistribution spotDistributionFromString(const std::string&);

/// Poisson-disk minimum distance as a fraction of the spacing d: Bridson's maximal sampling at
/// this radius gives about as many spots as the d-lattice (measured: see docs/technique.md).
constexpr double kPoissonRadius = 0.88;

struct SpotPlacement
{
    SpotDistribution distribution = SpotDistribution::Poisson;
    double spacing = 6.0;  ///< d, output voxels (> 0)
    double jitter = 0.25;  ///< Dmax in [0, 1] (jittered only)
    std::uint64_t seed = 1;
};

/// Spot centres inside `box` (continuous output-index bounds, inclusive).
/// @throw lic::InputError if the box would hold more than 2^26 spots (spacing far too small).
std::vector<openvdb::Vec3d> placeSpots(const SpotPlacement& p, const openvdb::BBoxd& box);

/// Choose among `candidates` a subset no two closer than `minDistance`, spread evenly: candidates
/// are visited in an order given by hash(seed, index) and kept when no kept one is within
/// `minDistance` (greedy Poisson-disk selection). Deterministic.
std::vector<openvdb::Vec3d> selectEvenly(const std::vector<openvdb::Vec3d>& candidates,
                                         double minDistance, std::uint64_t seed);

/// How evenly spots fill space (the seed's claim for Poisson-disk), measured over many probes
/// inside `box` (shrunk by the probe radius so every probe lies fully inside).
struct SpotStats
{
    std::size_t count = 0;
    double minDistance = 0;  ///< smallest centre distance (output voxels)
    double meanNearest = 0;  ///< mean nearest-neighbour distance
    /// Coefficient of variation (σ/μ) of the number of spots in thin discs (thickness d/2,
    /// radius 4d) on randomly oriented planes: Poisson-disk < random.
    double planeCov = 0;
    /// The same for axis-aligned discs of thickness d/4: lattices leave whole rows empty.
    double axisPlaneCov = 0;
    /// Fraction of those axis-aligned discs that contain no spot at all ("empty rows").
    double emptyAxisFraction = 0;
};
SpotStats spotStatistics(const std::vector<openvdb::Vec3d>& spots, const openvdb::BBoxd& box,
                         double spacing, std::uint64_t seed, int probes = 2000);

/// Smooth-edged sphere of radius r: 1 within r − w/2, 0 beyond r + w/2 and a C¹ smoothstep in
/// between, w = min(1, r) (one output voxel of anti-aliasing). Returns f(d); `slope` gets df/dd.
inline double spotProfile(double d, double r, double& slope)
{
    const double w = std::min(1.0, r);
    const double t = (d - (r - 0.5 * w)) / w;
    if (t <= 0.0) {
        slope = 0.0;
        return 1.0;
    }
    if (t >= 1.0) {
        slope = 0.0;
        return 0.0;
    }
    slope = -6.0 * t * (1.0 - t) / w;
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

/// Spot centres with an intensity each (1, or the region-of-interest weight at the centre).
struct SpotSet
{
    std::vector<openvdb::Vec3d> centers;
    std::vector<float> weights;
};

/// The concentric spot texture of K radius levels: channels 0..K−1 are the lines (radius r_k),
/// channels K..2K−1 their halos (radius R_k = haloScale·r_k). Evaluated analytically from a
/// uniform grid of spot buckets, so every value is exact and anti-aliased at any position (no
/// voxelisation). Because R_k ≥ r_k and the profile is monotonic, halo_k ≥ line_k everywhere.
/// Satisfies the texture concept of lic::convolve (kChannels, sample, sampleGradient).
/// With Halos = false only the K line channels exist (what a bake without halos would cost).
template<int K, bool Halos = true>
class SpotTexture
{
public:
    static constexpr int kChannels = Halos ? 2 * K : K;

    SpotTexture(const SpotSet& spots, const std::array<double, K>& radii, double haloScale)
        : mSpots(spots)
    {
        for (int k = 0; k < K; ++k) {
            mRadius[k] = radii[std::size_t(k)];
            if constexpr (Halos) mRadius[K + k] = radii[std::size_t(k)] * haloScale;
        }
        double reach = 0.0;
        for (double r : mRadius) reach = std::max(reach, r + 0.5 * std::min(1.0, r));
        mReach2 = reach * reach;
        // Cells of edge ≥ 2·reach: the 2×2×2 cells nearest a point hold every spot that touches it.
        mCell = 2.0 * reach + 1e-6;
        openvdb::Vec3d lo(1e300), hi(-1e300);
        for (const auto& c : mSpots.centers) {
            lo = openvdb::math::minComponent(lo, c);
            hi = openvdb::math::maxComponent(hi, c);
        }
        if (mSpots.centers.empty()) lo = hi = openvdb::Vec3d(0.0);
        for (int a = 0; a < 3; ++a) {
            mLo[a] = int(std::floor(lo[a] / mCell)) - 1;
            mDim[a] = int(std::floor(hi[a] / mCell)) - mLo[a] + 2;
        }
        const std::size_t nCells = std::size_t(mDim[0]) * std::size_t(mDim[1]) * std::size_t(mDim[2]);
        mStart.assign(nCells + 1, 0);
        std::vector<std::size_t> cellOf(mSpots.centers.size());
        for (std::size_t s = 0; s < mSpots.centers.size(); ++s) {
            cellOf[s] = cellIndex(cellCoord(mSpots.centers[s]));
            ++mStart[cellOf[s] + 1];
        }
        for (std::size_t c = 0; c < nCells; ++c) mStart[c + 1] += mStart[c];
        mOrder.resize(mSpots.centers.size());
        std::vector<std::uint32_t> fill(mStart.begin(), mStart.end() - 1);
        for (std::size_t s = 0; s < mSpots.centers.size(); ++s) mOrder[fill[cellOf[s]]++] = std::uint32_t(s);
    }

    std::size_t spotCount() const { return mSpots.centers.size(); }
    double radius(int channel) const { return mRadius[channel]; }

    void sample(const openvdb::Vec3d& p, float* out) const { sampleGradient(p, out, nullptr); }

    /// Values of all 2K channels at output-index position p and, if `grad` is non-null, their
    /// gradients (3 per channel, channel-major).
    void sampleGradient(const openvdb::Vec3d& p, float* out, float* grad) const
    {
        double v[kChannels] = {};
        double g[3 * kChannels] = {};
        visit(p, [&](std::uint32_t s, const openvdb::Vec3d& delta, double d) {
            add(s, delta, d, v, grad ? g : nullptr);
        });
        for (int k = 0; k < kChannels; ++k) out[k] = float(v[k]);
        if (grad)
            for (int k = 0; k < 3 * kChannels; ++k) grad[k] = float(g[k]);
    }

    /// sampleGradient one spot at a time: fn(spot index, values[kChannels], gradients[3·kChannels])
    /// for every spot that reaches p, in a fixed order (the fast engine's comet loops give each
    /// spot's part its own phase). The parts sum to sampleGradient's values (to rounding).
    template<typename Fn>
    void forEachSpot(const openvdb::Vec3d& p, Fn&& fn) const
    {
        visit(p, [&](std::uint32_t s, const openvdb::Vec3d& delta, double d) {
            double v[kChannels] = {};
            double g[3 * kChannels] = {};
            add(s, delta, d, v, g);
            float vf[kChannels], gf[3 * kChannels];
            for (int k = 0; k < kChannels; ++k) vf[k] = float(v[k]);
            for (int k = 0; k < 3 * kChannels; ++k) gf[k] = float(g[k]);
            fn(s, static_cast<const float*>(vf), static_cast<const float*>(gf));
        });
    }

    /// Centre of spot s (output index).
    const openvdb::Vec3d& centre(std::uint32_t s) const { return mSpots.centers[s]; }

private:
    /// fn(spot, p − centre, distance) for every spot within reach of p, in a fixed order.
    template<typename Fn>
    void visit(const openvdb::Vec3d& p, Fn&& fn) const
    {
        const std::array<int, 3> c0{detail::floorIndex(p[0] / mCell - 0.5), detail::floorIndex(p[1] / mCell - 0.5),
                                    detail::floorIndex(p[2] / mCell - 0.5)};
        for (int dx = 0; dx < 2; ++dx)
            for (int dy = 0; dy < 2; ++dy)
                for (int dz = 0; dz < 2; ++dz) {
                    const std::array<int, 3> c{c0[0] + dx, c0[1] + dy, c0[2] + dz};
                    bool inside = true;
                    for (int a = 0; a < 3; ++a) inside = inside && c[a] >= mLo[a] && c[a] < mLo[a] + mDim[a];
                    if (!inside) continue;
                    const std::size_t cell = cellIndex(c);
                    for (std::uint32_t i = mStart[cell]; i < mStart[cell + 1]; ++i) {
                        const std::uint32_t s = mOrder[i];
                        const openvdb::Vec3d delta = p - mSpots.centers[s];
                        const double d2 = delta.lengthSqr();
                        if (d2 >= mReach2) continue;
                        fn(s, delta, std::sqrt(d2));
                    }
                }
    }

    /// Add spot s's channel values (and gradients, if g) at offset delta, distance d, to v (g).
    void add(std::uint32_t s, const openvdb::Vec3d& delta, double d, double* v, double* g) const
    {
        const double a = mSpots.weights[s];
        for (int k = 0; k < kChannels; ++k) {
            double slope;
            const double f = spotProfile(d, mRadius[k], slope);
            v[k] += a * f;
            if (g && slope != 0.0 && d > 0.0) {
                const double q = a * slope / d;
                g[3 * k] += q * delta[0];
                g[3 * k + 1] += q * delta[1];
                g[3 * k + 2] += q * delta[2];
            }
        }
    }

    std::array<int, 3> cellCoord(const openvdb::Vec3d& p) const
    {
        return {detail::floorIndex(p[0] / mCell), detail::floorIndex(p[1] / mCell), detail::floorIndex(p[2] / mCell)};
    }
    std::size_t cellIndex(const std::array<int, 3>& c) const
    {
        return (std::size_t(c[0] - mLo[0]) * std::size_t(mDim[1]) + std::size_t(c[1] - mLo[1])) *
                   std::size_t(mDim[2]) +
               std::size_t(c[2] - mLo[2]);
    }

    const SpotSet& mSpots;
    std::array<double, kChannels> mRadius{};
    double mReach2 = 0, mCell = 1;
    std::array<int, 3> mLo{}, mDim{};
    std::vector<std::uint32_t> mStart, mOrder;
};

} // namespace lic

// The output-sensitive spot engine (`--engine splat`; Seed LIC, Helgeland & Andreassen 2004;
// Falk & Weiskopf 2008): one streamline per spot, and the spot's convolved footprint deposited
// around it, so work and memory grow with the lines (spots × length × radius²), not with the box.
//
// What a gather engine gives a voxel x for one spot s of profile f (radius r) is the kernel-weighted
// fraction of x's own streamline window that lies inside the spot:
//     I(x) = Σ_i w_i f(|σ_x(i·h) − s|) / Σ_i w_i.
// Where streamlines are locally parallel, σ_x runs beside the spot's own streamline σ_s at the
// perpendicular distance d of x from σ_s, and x's window is centred at the arc τ of x's foot point
// on σ_s (the spot at arc 0); so |σ_x(i·h) − s|² ≈ d² + (τ + i·h)² and
//     I(x) ≈ W(τ, d) = Σ_i w_i f(√(d² + (τ + i·h)²)) / Σ_i w_i,
// a function of two numbers, tabulated once per channel (and, for loops, with the ripple phases
// e^{iθi} as the gather engines carry them). The splat traces σ_s over the kernel's support, finds
// (τ, d) for every voxel within reach, and adds a_s·W(τ, d) (a_s the spot's weight). Sums over
// spots are exact by linearity. Where the spot's line ends at a wall within the support, x's window
// is cut there too: W is rescaled by Σ_all w_i / Σ_inside w_i (the spot's own samples are all inside,
// so only the normalisation changes). It differs from the gather where the flow diverges or
// converges across the tube (x's line drifts from σ_s over the window) and where a spot lies within
// its radius of a wall. docs/technique.md §10 has the derivation and the measured agreement.
//
// Deterministic: spots are traced independently; each brick then deposits the spots that reach it,
// in spot order, into its own voxels only.
#pragma once

#include "lic/engine/Driver.h"
#include "lic/engine/Engine.h"
#include "lic/engine/Settings.h"
#include "lic/texture/Spots.h"

#include <array>
#include <vector>

namespace lic {

/// W(τ, d) of every channel of a spot texture (radii `radii`, lines then halos), tabulated over
/// τ (arc offset of a voxel's foot point from the spot, output voxels) and d (distance from the
/// spot's streamline), for the settings' kernel; with `ripple` also Re and Im of the ripple sums.
class SplatTables
{
public:
    SplatTables(const std::vector<double>& radii, const LicSettings& settings);

    int channels() const { return mC; }
    /// Values per (τ, d): C (or 3C with ripple: A, then Re Z, then Im Z per channel).
    int parts() const { return mParts; }
    /// Largest distance from a spot's streamline at which any channel is non-zero.
    double reach() const { return mReach; }
    /// Support in τ: [tauMin, tauMax] (box: ±(n·h + reach); exp: [−(n·h + reach), reach]).
    double tauMin() const { return mTauMin; }
    double tauMax() const { return mTauMax; }
    /// Add a·W(τ, d) for every part to out[0 .. parts). No-op outside the support.
    void add(double tau, double d, float a, float* out) const;
    /// Start loading the table rows add(tau, d, …) will read (a hint; no effect on results).
    void prefetch(double tau, double d) const;
    /// The same sum worked out directly over window samples i0 … i1 only (a window cut by a wall),
    /// normalised by `weight`, the kernel weight of those samples: for spots within reach of a
    /// wall, where the part of the spot beyond the wall must not count.
    void addDirect(double tau, double d, float a, int i0, int i1, double weight, float* out) const;

private:
    /// The table entry at the lower corner of (τ, d)'s cell and the bilinear fractions; c00 null
    /// outside the support.
    struct Cell
    {
        const float* c00 = nullptr;
        float wt = 0, wd = 0;
    };
    Cell cell(double tau, double d) const;
    /// 1/step if step is a power of two (then x·(1/step) is x/step exactly), else 0.
    static double exactInverse(double step);

    std::vector<double> mRadii;
    double mH, mDecay, mTheta;
    bool mExp, mRipple;
    int mC, mParts;
    double mReach, mTauMin, mTauMax;
    double mDTau, mDD;
    // 1/ΔΤ and 1/Δd where they are powers of two (h = ½ and the default Δd), so that multiplying
    // by them gives the division's bits exactly; 0 where they are not (add() divides).
    double mInvDTau = 0, mInvDD = 0;
    int mNTau, mND;
    std::vector<double> mWeights; // exp: c^i, i = 0 … n
    std::vector<float> mTable; // [tau][d][part]
};

/// Comet loops (LicSettings::comets = N frames): every spot's streamline carries a train of
/// comets, copies of the spot at arcs a spaced P apart (cometSpacing()), moving P/N downstream per
/// frame, so frame N+1 is frame 1. A copy at arc a has amplitude cometFade(a, P) = cos²(πa / 2P) for
/// |a| < P, else 0: at every phase the two copies inside (−P, P) sum to the spot's own weight
/// (cos² + sin² = 1), so a line carries the same ink in every frame, and comets fade in upstream
/// and out downstream instead of popping. Each copy's footprint is the still's W(τ − a, d), so a
/// comet has the kernel's shape (box: a dash; exp: the tapered streamlet, head downstream).
/// Tabulated per phase g = 0 … N−1 (copies at (g/N − m)·P, m = 0, 1) from the still's tables, so
/// a voxel reads every frame from one bilinear lookup; a spot of phase k shows phase (f + k) mod N
/// in frame f (phases spread the comets of neighbouring lines).
class CometTables
{
public:
    CometTables(const SplatTables& still, const LicSettings& settings, double spacing);

    int frames() const { return mN; }
    double spacing() const { return mP; }
    /// Arc of copy m (0 or 1) at phase g.
    double copyArc(int g, int m) const { return (double(g) / double(mN) - double(m)) * mP; }
    /// cometFade(copyArc(g, m), P), precomputed.
    double copyFade(int g, int m) const { return mFade[std::size_t(2 * g + m)]; }
    double tauMin() const { return mTauMin; }
    double tauMax() const { return mTauMax; }
    /// Add a·(every frame's W) at (τ, d) to out[f·C + c], frame f showing phase (f + phase) mod N.
    void add(double tau, double d, float a, int phase, float* out) const;
    /// Add a·(phase g's W) at (τ, d) to out[0 .. C).
    void addPhase(double tau, double d, float a, int g, float* out) const;

private:
    /// The four table rows around (τ, d) and their bilinear weights times a (p[0] null outside).
    struct Corners
    {
        std::array<const float*, 4> p{};
        std::array<float, 4> w{};
    };
    Corners corners(double tau, double d, float a) const;

    int mN, mC;
    double mP, mTauMin, mTauMax, mReach, mDTau, mDD;
    int mNTau, mND;
    std::vector<double> mFade; // [phase][copy]
    std::vector<float> mTable; // [tau][d][phase][channel]
};


/// The splat engine's entry in the engine table: the same channels a gather engine delivers for
/// spots (2K, or 3·2K + 2 for a loop), brick by brick, only for bricks some spot's footprint
/// reaches (others have nothing to show). Blocks no footprint touches are flagged in
/// BrickChannels::blockTouched and their values are not set.
/// @throw lic::InputError for invalid settings or radii; lic::Cancelled.
LicStats splatSpotBricks(const ConvolveJob& job, const SpotInput& spots, const BrickSink& sink);

/// The splat engine's policy (its row of the engine table): 64³ bricks whatever the kernel (32³ for
/// comet loops, whose N·C accumulators per voxel would not stay in cache); the
/// reach of a spot (its line's support and the footprint the rasteriser covers around it); the
/// field its lines sample.
int splatBrickDim(const LicSettings& settings);
double splatSpotReach(const LicSettings& settings, double maxSpotRadius);
double splatFieldReach(const LicSettings& settings, bool spots, double maxSpotRadius, int stride);

} // namespace lic

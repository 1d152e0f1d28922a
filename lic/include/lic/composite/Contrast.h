// Contrast normalisation of raw LIC values to [0, 1]: LIC of white noise averages ~2n samples, so
// its values crowd around 0.5 with a spread of only a few percent (a grey mush). The stretch maps
// mean ± `sigmas` standard deviations linearly onto [0, 1] and clamps. One implementation: the
// whole-volume functions below and a bake's compositor (which gathers the moments brick by brick)
// both use Moments and ContrastStretch.
#pragma once

#include "lic/field/OutputDomain.h"

#include <algorithm>
#include <limits>
#include <vector>

namespace lic {

/// Mean and standard deviation (and range) of a channel over some voxels.
struct ChannelStats
{
    double mean = 0, stddev = 0, min = 0, max = 0;
};

/// Running sums of a channel's values, merged in a fixed order (per block, per brick) so the
/// statistics are the same bits for any thread count.
struct Moments
{
    double sum = 0, sumSq = 0, count = 0;
    float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();

    void add(float v)
    {
        sum += v;
        sumSq += double(v) * v;
        count += 1;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    void merge(const Moments& o)
    {
        sum += o.sum;
        sumSq += o.sumSq;
        count += o.count;
        lo = std::min(lo, o.lo);
        hi = std::max(hi, o.hi);
    }
    /// Statistics of the values added (all zero when there were none).
    ChannelStats stats() const;
};

/// The contrast stretch of a channel with statistics `stats`: v ↦ clamp((v − (mean − σ·sd)) /
/// (2σ·sd), 0, 1). A (nearly) constant channel (sd < 1e-6), or `enabled` false, leaves v as it is.
class ContrastStretch
{
public:
    static constexpr double kSigmas = 2.5;
    explicit ContrastStretch(const ChannelStats& stats, double sigmas = kSigmas, bool enabled = true);
    bool active() const { return mActive; }
    double operator()(double v) const { return mActive ? std::clamp((v - mLo) * mScale, 0.0, 1.0) : v; }

private:
    double mLo = 0.0, mScale = 1.0;
    bool mActive = false;
};

/// Statistics of a per-slot channel over the domain's active voxels (per-block moments merged in
/// block order: deterministic).
ChannelStats channelStats(const OutputDomain& domain, const std::vector<float>& slots);

/// Stretch a per-slot channel in place (ContrastStretch of its own statistics). Returns the
/// statistics before stretching.
ChannelStats contrastStretch(const OutputDomain& domain, std::vector<float>& slots,
                             double sigmas = ContrastStretch::kSigmas);

/// Apply the stretch of `stats` (from contrastStretch on another frame) to `slots`, so every frame
/// of a loop shares one mapping.
void applyContrast(const OutputDomain& domain, std::vector<float>& slots, const ChannelStats& stats,
                   double sigmas = ContrastStretch::kSigmas);

} // namespace lic

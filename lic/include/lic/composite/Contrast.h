// Contrast normalisation of raw LIC values to [0, 1].
#pragma once

#include "lic/field/OutputDomain.h"

#include <string>
#include <vector>

namespace lic {

/// Mean and standard deviation of a per-slot channel over the domain's active voxels
/// (deterministic: per-block sums combined in block order).
struct ChannelStats
{
    double mean = 0, stddev = 0, min = 0, max = 0;
};
ChannelStats channelStats(const OutputDomain& domain, const std::vector<float>& slots);

/// Contrast stretch: LIC of white noise averages ~2n samples, so its values crowd around 0.5 with
/// a spread of only a few percent (a grey mush). Map mean ± `sigmas` standard deviations linearly
/// onto [0, 1] and clamp. A (nearly) constant channel (stddev < 1e-6) is left as it is.
/// Returns the statistics before stretching.
ChannelStats contrastStretch(const OutputDomain& domain, std::vector<float>& slots,
                             double sigmas = 2.5);

/// Apply the stretch of `stats` (from contrastStretch on another frame) to `slots`, so every frame
/// of a loop shares one mapping.
void applyContrast(const OutputDomain& domain, std::vector<float>& slots, const ChannelStats& stats,
                   double sigmas = 2.5);

} // namespace lic

#include "lic/composite/Contrast.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace lic {

ChannelStats Moments::stats() const
{
    ChannelStats s;
    if (count == 0) return s;
    s.mean = sum / count;
    s.stddev = std::sqrt(std::max(0.0, sumSq / count - s.mean * s.mean));
    s.min = lo;
    s.max = hi;
    return s;
}

ContrastStretch::ContrastStretch(const ChannelStats& stats, double sigmas, bool enabled)
    : mActive(enabled && stats.stddev >= 1e-6)
{
    mLo = stats.mean - sigmas * stats.stddev;
    mScale = mActive ? 1.0 / (2.0 * sigmas * stats.stddev) : 1.0;
}

ChannelStats channelStats(const OutputDomain& domain, const std::vector<float>& slots)
{
    std::vector<Moments> parts(domain.blockCount());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, domain.blockCount()), [&](const auto& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b)
            for (auto on = domain.blockMask(b).beginOn(); on; ++on)
                parts[b].add(slots[b * OutputDomain::kBlockVoxels + on.pos()]);
    });
    Moments all;
    for (const Moments& p : parts) all.merge(p);
    return all.stats();
}

ChannelStats contrastStretch(const OutputDomain& domain, std::vector<float>& slots, double sigmas)
{
    const ChannelStats s = channelStats(domain, slots);
    applyContrast(domain, slots, s, sigmas);
    return s;
}

void applyContrast(const OutputDomain& domain, std::vector<float>& slots, const ChannelStats& s, double sigmas)
{
    const ContrastStretch stretch(s, sigmas);
    if (!stretch.active()) return;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slots.size()), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
            if (domain.isActive(i)) slots[i] = float(stretch(double(slots[i])));
    });
}

} // namespace lic

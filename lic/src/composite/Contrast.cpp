#include "lic/composite/Contrast.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace lic {

ChannelStats channelStats(const OutputDomain& domain, const std::vector<float>& slots)
{
    struct Partial
    {
        double sum = 0, sumSq = 0;
        float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    };
    std::vector<Partial> parts(domain.blockCount());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, domain.blockCount()), [&](const auto& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            const auto& mask = domain.blockMask(b);
            Partial p;
            for (auto on = mask.beginOn(); on; ++on) {
                const std::size_t off = on.pos();
                const float v = slots[b * OutputDomain::kBlockVoxels + off];
                p.sum += v;
                p.sumSq += double(v) * v;
                p.lo = std::min(p.lo, v);
                p.hi = std::max(p.hi, v);
            }
            parts[b] = p;
        }
    });
    Partial all;
    for (const Partial& p : parts) {
        all.sum += p.sum;
        all.sumSq += p.sumSq;
        all.lo = std::min(all.lo, p.lo);
        all.hi = std::max(all.hi, p.hi);
    }
    ChannelStats s;
    const double n = double(domain.activeVoxelCount());
    if (n == 0) return s;
    s.mean = all.sum / n;
    s.stddev = std::sqrt(std::max(0.0, all.sumSq / n - s.mean * s.mean));
    s.min = all.lo;
    s.max = all.hi;
    return s;
}

ChannelStats contrastStretch(const OutputDomain& domain, std::vector<float>& slots, double sigmas)
{
    const ChannelStats s = channelStats(domain, slots);
    applyContrast(domain, slots, s, sigmas);
    return s;
}

void applyContrast(const OutputDomain& domain, std::vector<float>& slots, const ChannelStats& s, double sigmas)
{
    if (s.stddev < 1e-6) return;
    const double lo = s.mean - sigmas * s.stddev;
    const double scale = 1.0 / (2.0 * sigmas * s.stddev);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slots.size()), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            if (!domain.isActive(i)) continue;
            slots[i] = float(std::clamp((double(slots[i]) - lo) * scale, 0.0, 1.0));
        }
    });
}

} // namespace lic

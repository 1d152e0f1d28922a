#include "lic/Contrast.h"
#include "lic/Engine.h"
#include "lic/Noise.h"

#include "TestFields.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace lic;

namespace {

struct Compare
{
    double correlation = 0, meanAbsDiff = 0;
};

Compare compare(const OutputDomain& d, const std::vector<float>& a, const std::vector<float>& b)
{
    double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0, mad = 0, n = 0;
    for (std::size_t s = 0; s < a.size(); ++s) {
        if (!d.isActive(s)) continue;
        sa += a[s], sb += b[s], saa += double(a[s]) * a[s], sbb += double(b[s]) * b[s];
        sab += double(a[s]) * b[s], mad += std::abs(double(a[s]) - b[s]), n += 1;
    }
    const double ca = saa / n - (sa / n) * (sa / n), cb = sbb / n - (sb / n) * (sb / n);
    return {(sab / n - sa / n * sb / n) / std::sqrt(ca * cb), mad / n};
}

} // namespace

TEST(Engine, FastMatchesNaiveOnAbcNoise)
{
    VelocityField field(lictest::abcField(32));
    OutputDomain domain(field, 2);
    NoiseTexture noise(7);
    LicSettings s;
    s.length = 20;
    s.step = 0.5;
    s.engine = EngineType::Naive;
    LicResult naive = convolve(field, domain, noise, s);
    s.engine = EngineType::Fast;
    LicResult fast = convolve(field, domain, noise, s);
    contrastStretch(domain, naive.channels[0]);
    contrastStretch(domain, fast.channels[0]);
    const Compare c = compare(domain, naive.channels[0], fast.channels[0]);
    std::printf("voxels %llu naive %.2fs fast %.2fs (x%.1f) samples/voxel naive %.1f fast %.2f streamlines %llu rounds %d\n",
                (unsigned long long)domain.activeVoxelCount(), naive.stats.seconds, fast.stats.seconds,
                naive.stats.seconds / fast.stats.seconds, naive.stats.samplesPerVoxel(),
                fast.stats.samplesPerVoxel(), (unsigned long long)fast.stats.streamlines, fast.stats.rounds);
    std::printf("correlation %.4f mean abs diff %.4f\n", c.correlation, c.meanAbsDiff);
    EXPECT_GE(c.correlation, 0.99);
    EXPECT_LE(c.meanAbsDiff, 0.02);
}

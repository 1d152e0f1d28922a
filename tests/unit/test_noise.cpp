#include "lic/util/Error.h"
#include "lic/texture/Noise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

using namespace lic;
using openvdb::Coord;
using openvdb::CoordBBox;

TEST(Noise, WhiteNoiseIsUniformInUnitInterval)
{
    double sum = 0, sumSq = 0;
    const int n = 40;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k) {
                const float v = whiteNoise(3, i, j, k);
                ASSERT_GE(v, 0.0f);
                ASSERT_LT(v, 1.0f);
                sum += v;
                sumSq += double(v) * v;
            }
    const double N = double(n) * n * n, mean = sum / N, var = sumSq / N - mean * mean;
    EXPECT_NEAR(mean, 0.5, 0.005);
    EXPECT_NEAR(var, 1.0 / 12.0, 0.002);
    EXPECT_NE(whiteNoise(3, 1, 2, 3), whiteNoise(4, 1, 2, 3));
    EXPECT_NE(whiteNoise(3, 1, 2, 3), whiteNoise(3, 2, 1, 3));
    EXPECT_NE(whiteNoise(3, -1, 0, 0), whiteNoise(3, 1, 0, 0));
}

TEST(Noise, AnyRegionRegeneratesIndependently)
{
    for (NoiseFilter f : {NoiseFilter::None, NoiseFilter::Binomial}) {
        NoiseTexture big(11, CoordBBox(Coord(-10), Coord(30)), f);
        NoiseTexture small(11, CoordBBox(Coord(5, 6, 7), Coord(9, 9, 9)), f);
        for (int i = 5; i <= 9; ++i)
            for (int j = 6; j <= 9; ++j)
                for (int k = 7; k <= 9; ++k) ASSERT_EQ(big.voxel(Coord(i, j, k)), small.voxel(Coord(i, j, k)));
    }
}

TEST(Noise, BinomialFilterIsTheWeightedNeighbourhoodMean)
{
    NoiseTexture t(5, CoordBBox(Coord(0), Coord(6)), NoiseFilter::Binomial);
    const float w[3] = {0.25f, 0.5f, 0.25f};
    for (const Coord c : {Coord(0), Coord(3, 2, 1), Coord(6, 6, 6)}) {
        double expect = 0;
        for (int a = -1; a <= 1; ++a)
            for (int b = -1; b <= 1; ++b)
                for (int d = -1; d <= 1; ++d)
                    expect += w[a + 1] * w[b + 1] * w[d + 1] * whiteNoise(5, c[0] + a, c[1] + b, c[2] + d);
        EXPECT_NEAR(t.voxel(c), expect, 1e-6) << c;
    }
}

TEST(Noise, TrilinearBetweenCentresWithGradient)
{
    NoiseTexture t(9, CoordBBox(Coord(0), Coord(4)), NoiseFilter::None);
    float v, g[3];
    t.sampleGradient(openvdb::Vec3d(1, 2, 3), &v, g);
    EXPECT_FLOAT_EQ(v, whiteNoise(9, 1, 2, 3));
    t.sample(openvdb::Vec3d(1.5, 2, 3), &v);
    EXPECT_NEAR(v, 0.5f * (whiteNoise(9, 1, 2, 3) + whiteNoise(9, 2, 2, 3)), 1e-6);
    t.sampleGradient(openvdb::Vec3d(1.25, 2, 3), &v, g);
    EXPECT_NEAR(g[0], whiteNoise(9, 2, 2, 3) - whiteNoise(9, 1, 2, 3), 1e-6);
    EXPECT_THROW(noiseFilterFromString("gauss"), Error);
}

TEST(Noise, ABricksNoiseClippedToTheReachSamplesTheSame)
{
    // A brick at a corner of the reach (the field's output voxels, as gatherNoiseBricks clips):
    // the clipped texture is smaller than the brick grown by its margin, and every lookup inside
    // the reach, up to half a voxel past its outermost centres, gives the same value and gradient
    // bits as the unclipped texture.
    const CoordBBox reach(Coord(0), Coord(47));
    Brick brick;
    brick.box = CoordBBox(Coord(0), Coord(15));
    NoiseBrickSource whole(4, NoiseFilter::Binomial, 20), clipped(4, NoiseFilter::Binomial, 20);
    clipped.clipTo(reach.expandBy(1));
    const NoiseTexture& a = whole(brick);
    const NoiseTexture& b = clipped(brick);
    EXPECT_EQ(a.box(), CoordBBox(Coord(-20), Coord(35)));
    EXPECT_EQ(b.box(), CoordBBox(Coord(-1), Coord(35)));
    std::uint32_t state = 12345;
    auto uniform = [&](double lo, double hi) {
        state = state * 1664525u + 1013904223u;
        return lo + (hi - lo) * double(state >> 8) / double(1u << 24);
    };
    for (int s = 0; s < 20000; ++s) {
        openvdb::Vec3d p(uniform(-0.5, 47.5), uniform(-0.5, 47.5), uniform(-0.5, 47.5));
        if (s % 4 == 0) p[s % 3] = (s / 4) % 2 ? 47.5 : -0.5; // on the reach's faces
        float va[4], vb[4];
        a.sampleGradient(p, va, va + 1);
        b.sampleGradient(p, vb, vb + 1);
        for (int c = 0; c < 4; ++c) ASSERT_EQ(std::memcmp(&va[c], &vb[c], sizeof(float)), 0) << p << " component " << c;
    }
}

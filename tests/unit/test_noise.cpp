#include "lic/util/Error.h"
#include "lic/texture/Noise.h"

#include <gtest/gtest.h>

#include <cmath>

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

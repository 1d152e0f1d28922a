#include "lic/composite/Colormap.h"
#include "lic/util/Error.h"

#include <gtest/gtest.h>

using namespace lic;
using openvdb::Vec3d;

TEST(Colormap, SrgbDecode)
{
    EXPECT_DOUBLE_EQ(srgbToLinear(0.0), 0.0);
    EXPECT_NEAR(srgbToLinear(1.0), 1.0, 1e-12);
    EXPECT_NEAR(srgbToLinear(0.5), 0.214041, 1e-6);
    EXPECT_NEAR(srgbToLinear(0.04), 0.04 / 12.92, 1e-12);
}

TEST(Colormap, AllNamedMapsExistAndSpanTheirEnds)
{
    ASSERT_EQ(Colormap::names().size(), 8u);
    for (const auto& n : Colormap::names()) {
        const Colormap m = Colormap::named(n);
        EXPECT_EQ(m.name(), n);
        EXPECT_DOUBLE_EQ(m.points().front().first, 0.0);
        EXPECT_DOUBLE_EQ(m.points().back().first, 1.0);
        EXPECT_EQ(m.srgb(-1.0), m.points().front().second) << n;
        EXPECT_EQ(m.srgb(2.0), m.points().back().second) << n;
        for (double t = 0; t <= 1.0; t += 0.01) {
            const Vec3d c = m.linear(t);
            for (int a = 0; a < 3; ++a) {
                EXPECT_GE(c[a], 0.0) << n;
                EXPECT_LE(c[a], 1.0) << n;
            }
        }
    }
    EXPECT_THROW(Colormap::named("jet"), InputError);
}

TEST(Colormap, SequentialMapsHaveMonotonicLuminance)
{
    for (const std::string n : {"viridis", "magma", "inferno", "cividis", "heated-object", "red-yellow"}) {
        const Colormap m = Colormap::named(n);
        double prev = -1;
        for (int i = 0; i <= 200; ++i) {
            const double y = luminance(m.linear(i / 200.0));
            EXPECT_GT(y, prev) << n << " at t = " << i / 200.0;
            prev = y;
        }
    }
    // coolwarm is diverging: lightest in the middle.
    const Colormap cw = Colormap::named("coolwarm");
    EXPECT_GT(luminance(cw.linear(0.5)), luminance(cw.linear(0.0)));
    EXPECT_GT(luminance(cw.linear(0.5)), luminance(cw.linear(1.0)));
    // grey-purple is a saturation wash: grey at 0, saturated at 1.
    const Colormap gp = Colormap::named("grey-purple");
    const Vec3d g0 = gp.srgb(0), g1 = gp.srgb(1);
    EXPECT_NEAR(g0[0], g0[2], 1e-9);
    EXPECT_GT(g1[2] - g1[1], 0.5);
}

TEST(Colormap, InterpolatesInSrgb)
{
    const Colormap m = Colormap::fromCsv("0,0,0,0\n10,1,1,1\n", "lut.csv");
    EXPECT_NEAR(m.srgb(0.5)[1], 0.5, 1e-12);
    EXPECT_NEAR(m.linear(0.5)[1], srgbToLinear(0.5), 1e-12);
}

TEST(Colormap, CsvLuts)
{
    const Colormap m = Colormap::fromCsv("# value,r,g,b\n-1, 0, 0, 255\n\n0, 0, 255, 0 # green\n3, 255,0,0\n", "my.csv");
    ASSERT_EQ(m.points().size(), 3u);
    EXPECT_NEAR(m.points()[1].first, 0.25, 1e-12); // -1..3 remapped to 0..1
    EXPECT_NEAR(m.srgb(0.25)[1], 1.0, 1e-12);      // 0–255 input scaled
    auto expectError = [](const std::string& text, const std::string& word) {
        try {
            Colormap::fromCsv(text, "bad.csv");
            FAIL() << "accepted: " << text;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    expectError("0,0,0\n1,1,1,1\n", "bad.csv:1");
    expectError("0,0,0,0\n0,1,1,1\n", "greater");
    expectError("0,0,0,0\n", "at least 2");
    expectError("0,0,0,0\n1,1,1,1,1\n", "bad.csv:2");
    expectError("0,0,0,0\n1,300,1,1\n", "[0, 255]");
    expectError("0,0,0,0\n1,-1,1,1\n", ">= 0");
}

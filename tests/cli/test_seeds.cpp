// End-to-end tests of explicit spot centres (`--seeds FILE`, recipe `input.seeds`): lines run
// exactly through the given world points in a uniform flow, .npy and text give the same bake, a
// seeds file equal to the regular lattice gives the regular bake, points off the output domain are
// dropped and counted, the bake is bit-identical for 1 and 2 threads, and every bad file exits 2
// naming the file and the problem.
#include <gtest/gtest.h>

#include "CliRun.h"
#include "../unit/TempDirSuite.h"

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nlohmann::json;
using cli_test::RunResult;
using openvdb::Vec3d;

namespace {

/// `points` as text lines "x y z" with 17 significant digits (read back exactly).
std::string seedText(const std::vector<Vec3d>& points)
{
    std::string s = "# world-space seed points\n\n";
    char line[128];
    for (const auto& p : points) {
        std::snprintf(line, sizeof(line), "%.17g %.17g %.17g  # a seed\n", p[0], p[1], p[2]);
        s += line;
    }
    return s;
}

/// A .npy file (format 1.0) with header dict `dict` and raw data `data`.
std::string npyBytes(const std::string& dict, const std::string& data)
{
    std::string header = dict;
    while ((10 + header.size() + 1) % 64 != 0) header += ' ';
    header += '\n';
    std::string out("\x93NUMPY\x01\x00", 8);
    out += char(header.size() & 0xff);
    out += char(header.size() >> 8);
    return out + header + data;
}

/// `points` as a little-endian float64 (N, 3) C-order .npy file.
std::string seedNpy(const std::vector<Vec3d>& points)
{
    std::string data(points.size() * 3 * sizeof(double), '\0');
    for (std::size_t i = 0; i < points.size(); ++i) std::memcpy(&data[i * 24], points[i].asPointer(), 24);
    return npyBytes("{'descr': '<f8', 'fortran_order': False, 'shape': (" + std::to_string(points.size()) + ", 3), }", data);
}

openvdb::FloatGrid::Ptr readFloat(const fs::path& p, const std::string& name)
{
    openvdb::io::File file(p.string());
    file.open(false);
    auto grid = openvdb::GridBase::grid<openvdb::FloatGrid>(file.readGrid(name));
    file.close();
    return grid;
}

/// Every active voxel of `a` and `b` holds the same bits (and the same voxels are active).
void expectBitIdentical(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b, const std::string& what)
{
    EXPECT_EQ(a.activeVoxelCount(), b.activeVoxelCount()) << what;
    EXPECT_TRUE(a.tree().hasSameTopology(b.tree())) << what;
    auto acc = b.getConstAccessor();
    std::size_t differ = 0;
    for (auto it = a.cbeginValueOn(); it; ++it) {
        const float va = *it, vb = acc.getValue(it.getCoord());
        if (std::memcmp(&va, &vb, sizeof(float)) != 0 && differ++ == 0)
            ADD_FAILURE() << what << ": first difference at " << it.getCoord() << ": " << va << " vs " << vb;
    }
    EXPECT_EQ(differ, 0u) << what;
}

/// Each test runs licvdb in its own directory (`work`), with a 16³ uniform flow v = (1, 0, 0).
class SeedsTest : public lictest::TempDirTest
{
protected:
    SeedsTest() : TempDirTest({"work", "logs"}) {}
    void SetUp() override
    {
        TempDirTest::SetUp();
        const RunResult r = run({"field", "uniform", "--res", "16,16,16", "--out", work("u.vdb"), "--quiet"});
        ASSERT_EQ(r.code, 0) << r.describe();
    }

    std::string work(const std::string& name) const { return (mDir / "work" / name).string(); }
    RunResult run(const std::vector<std::string>& args) { return cli_test::runLicvdb(mDir / "work", mDir / "logs", args); }
    void writeFile(const std::string& name, const std::string& bytes) { std::ofstream(work(name), std::ios::binary) << bytes; }

    /// A spot bake of the uniform flow into `out` (length 6 output voxels, splat engine); `extra` appended.
    RunResult bake(const std::string& out, std::vector<std::string> extra)
    {
        std::vector<std::string> args{"bake", "--field", work("u.vdb"), "--out", work(out), "--input", "spots",
                                      "--length", "6", "--step", "0.5", "--json"};
        args.insert(args.end(), extra.begin(), extra.end());
        return run(args);
    }

    /// The output transform and domain index box of a bake of this field (from a throwaway bake).
    void outputGeometry(openvdb::math::Transform::Ptr& xform, openvdb::CoordBBox& box)
    {
        writeFile("probe.txt", "0 0 0\n");
        const RunResult r = bake("probe.vdb", {"--seeds", "probe.txt", "--quiet"});
        ASSERT_EQ(r.code, 0) << r.describe();
        xform = readFloat(work("probe.vdb"), "density")->transform().copy();
        const json b = json::parse(r.out)["output_bbox"];
        box = openvdb::CoordBBox(openvdb::Coord(b[0][0], b[0][1], b[0][2]), openvdb::Coord(b[1][0], b[1][1], b[1][2]));
    }
};

TEST_F(SeedsTest, LinesRunThroughTheSeedsAndNowhereElse)
{
    openvdb::math::Transform::Ptr xform;
    openvdb::CoordBBox box;
    outputGeometry(xform, box);
    ASSERT_TRUE(xform);
    // Two seeds on output voxel centres, far from each other and from the domain's faces.
    const std::vector<openvdb::Coord> at{openvdb::Coord(15, 9, 11), openvdb::Coord(16, 22, 20)};
    std::vector<Vec3d> world;
    for (const auto& c : at) world.push_back(xform->indexToWorld(c));
    writeFile("s.txt", seedText(world));
    const RunResult r = bake("o.vdb", {"--seeds", "s.txt"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json spots = json::parse(r.out)["spots"];
    EXPECT_EQ(spots["count"], 2);
    EXPECT_EQ(spots["placement"], "seeds");
    EXPECT_EQ(spots["seeds"]["points"], 2);
    EXPECT_EQ(spots["seeds"]["dropped"], 0);
    const auto density = readFloat(work("o.vdb"), "density");
    auto acc = density->getConstAccessor();
    // Along the flow through each seed (within the kernel's reach) the line's core: close to 1.
    for (const auto& c : at)
        for (int dx = -3; dx <= 3; ++dx)
            EXPECT_GT(acc.getValue(c.offsetBy(dx, 0, 0)), 0.9f) << "on the line through " << c << " at dx " << dx;
    // Anywhere else nothing: a voxel with density lies within the spot radius + ½ voxel of
    // antialiasing (1.5 output voxels) of a line, and within length + 1.5 of its seed along x.
    std::size_t lit = 0;
    for (auto it = density->cbeginValueOn(); it; ++it) {
        if (*it <= 0.0f) continue;
        ++lit;
        bool near = false;
        for (const auto& c : at) {
            const openvdb::Coord d = it.getCoord() - c;
            near = near || (std::hypot(d.y(), d.z()) < 1.5 && std::abs(d.x()) <= 6 + 1.5);
        }
        EXPECT_TRUE(near) << "density " << *it << " at " << it.getCoord() << ", away from both lines";
    }
    EXPECT_GT(lit, 2u * 13u);
}

TEST_F(SeedsTest, NpyAndTextBakeTheSameBitsForOneAndTwoThreads)
{
    std::vector<Vec3d> points{{0.1, -0.2, 0.3}, {-0.45, 0.5, -0.35}, {0.6, 0.05, 0.55}, {-0.7, -0.6, 0.0}};
    writeFile("s.txt", seedText(points));
    writeFile("s.npy", seedNpy(points));
    const RunResult rt = bake("t.vdb", {"--seeds", "s.txt", "--threads", "1", "--quiet"});
    const RunResult rn = bake("n.vdb", {"--seeds", "s.npy", "--threads", "2", "--quiet"});
    ASSERT_EQ(rt.code, 0) << rt.describe();
    ASSERT_EQ(rn.code, 0) << rn.describe();
    EXPECT_EQ(json::parse(rt.out)["spots"]["count"], 4);
    for (const char* grid : {"density", "halo"})
        expectBitIdentical(*readFloat(work("t.vdb"), grid), *readFloat(work("n.vdb"), grid),
                           std::string(grid) + ": text, 1 thread vs .npy, 2 threads");
    // The resolved recipe names the seeds file, and its checksum is on `density`.
    const auto density = readFloat(work("n.vdb"), "density");
    EXPECT_EQ(json::parse(density->metaValue<std::string>("licvdb_recipe"))["input"]["seeds"], "s.npy");
    EXPECT_EQ(density->metaValue<std::string>("lic_seeds_sha256").size(), 64u);
}

TEST_F(SeedsTest, SeedsAtTheRegularLatticeGiveTheRegularBake)
{
    const RunResult reg = bake("reg.vdb", {"--distribution", "regular", "--spacing", "8", "--quiet"});
    ASSERT_EQ(reg.code, 0) << reg.describe();
    const auto regular = readFloat(work("reg.vdb"), "density");
    const json b = json::parse(reg.out)["output_bbox"];
    // placeSpots' regular lattice: centres (i + ½)·d inside the box of voxel bounds, x outermost.
    std::vector<Vec3d> points;
    const double d = 8.0;
    const auto inside = [&](double c, int a) { return c >= b[0][a].get<double>() - 0.5 && c <= b[1][a].get<double>() + 0.5; };
    for (int i = -4; i < 12; ++i)
        for (int j = -4; j < 12; ++j)
            for (int k = -4; k < 12; ++k) {
                const Vec3d c((i + 0.5) * d, (j + 0.5) * d, (k + 0.5) * d);
                if (inside(c[0], 0) && inside(c[1], 1) && inside(c[2], 2)) points.push_back(regular->indexToWorld(c));
            }
    writeFile("lattice.txt", seedText(points));
    const RunResult seeded = bake("seeded.vdb", {"--seeds", "lattice.txt", "--quiet"});
    ASSERT_EQ(seeded.code, 0) << seeded.describe();
    EXPECT_EQ(json::parse(seeded.out)["spots"]["count"], json::parse(reg.out)["spots"]["count"]);
    const auto s = readFloat(work("seeded.vdb"), "density");
    EXPECT_EQ(s->activeVoxelCount(), regular->activeVoxelCount());
    auto acc = s->getConstAccessor();
    float worst = 0.0f;
    for (auto it = regular->cbeginValueOn(); it; ++it) worst = std::max(worst, std::abs(*it - acc.getValue(it.getCoord())));
    EXPECT_LT(worst, 1e-5f) << "world → index rounding only";
}

TEST_F(SeedsTest, PointsOffTheDomainAreDroppedAndCounted)
{
    writeFile("s.txt", "0 0 0\n5 0 0\n0 -7 0\n0.25 0.25 0.25\n");
    const RunResult r = bake("o.vdb", {"--seeds", "s.txt"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json spots = json::parse(r.out)["spots"];
    EXPECT_EQ(spots["count"], 2);
    EXPECT_EQ(spots["seeds"]["points"], 4);
    EXPECT_EQ(spots["seeds"]["dropped"], 2);
    EXPECT_NE(r.err.find("2 of 4 seed points of s.txt lie outside the output domain"), std::string::npos) << r.describe();
    const RunResult quiet = bake("q.vdb", {"--seeds", "s.txt", "--quiet"});
    ASSERT_EQ(quiet.code, 0) << quiet.describe();
    EXPECT_EQ(quiet.err, "");
}

TEST_F(SeedsTest, AnUnsteadySequenceRefusesSeeds)
{
    ASSERT_EQ(run({"field", "uniform", "--res", "8,8,8", "--frames", "1,2", "--out", work("f_####.vdb"), "--quiet"}).code, 0);
    writeFile("s.txt", "0 0 0\n");
    const RunResult r = run({"bake", "--field", work("f_####.vdb"), "--field-frames", "1,2", "--out", work("o.vdb"),
                             "--input", "spots", "--seeds", "s.txt", "--length", "4"});
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_NE(r.err.find("not available with an unsteady field sequence"), std::string::npos) << r.describe();
}

struct BadSeeds
{
    const char* name;
    std::string file, bytes;
    std::vector<std::string> extra; ///< more flags
    std::vector<std::string> expect;
};

std::vector<BadSeeds> badSeeds()
{
    const std::string f8 = "{'descr': '<f8', 'fortran_order': False, 'shape': ";
    const double nanRow[6] = {0, 0, 0, 1, std::numeric_limits<double>::quiet_NaN(), 0};
    const std::string nanData(reinterpret_cast<const char*>(nanRow), sizeof(nanRow));
    return {
        {"missing", "", "", {"--seeds", "none.txt"}, {"input.seeds", "none.txt", "not found"}},
        {"not_three_numbers", "a.txt", "0 0 0\n# ok\n\n1 2\n", {}, {"a.txt", "line 4", "three numbers"}},
        {"a_word", "w.txt", "0 0 zero\n", {}, {"w.txt", "line 1", "three numbers"}},
        {"four_numbers", "f.xyz", "0 0 0 1\n", {}, {"f.xyz", "line 1", "three numbers"}},
        {"text_nan", "n.txt", "0 0 0\n1 nan 2\n", {}, {"n.txt", "line 2", "NaN or infinite"}},
        {"text_inf", "i.txt", "1 2 inf\n", {}, {"i.txt", "line 1", "NaN or infinite"}},
        {"no_points", "e.txt", "# nothing here\n\n", {}, {"e.txt", "no seed points"}},
        {"npy_shape", "s.npy", npyBytes(f8 + "(2, 2), }", std::string(32, '\0')), {}, {"s.npy", "shape (2, 2)", "(N, 3)"}},
        {"npy_1d", "v.npy", npyBytes(f8 + "(3,), }", std::string(24, '\0')), {}, {"v.npy", "shape (3,)", "(N, 3)"}},
        {"npy_dtype", "i.npy", npyBytes("{'descr': '<i4', 'fortran_order': False, 'shape': (1, 3), }", std::string(12, '\0')),
         {}, {"i.npy", "dtype '<i4'", "float32 or float64"}},
        {"npy_nan", "n.npy", npyBytes(f8 + "(2, 3), }", nanData), {}, {"n.npy", "row 1", "NaN or infinite"}},
        {"npy_empty", "z.npy", npyBytes(f8 + "(0, 3), }", ""), {}, {"z.npy", "no seed points"}},
        {"npy_absurd", "big.npy", npyBytes(f8 + "(60000000, 3), }", std::string(24, '\0')), {}, {"big.npy", "60000000", "limit"}},
        {"npy_truncated", "t.npy", npyBytes(f8 + "(4, 3), }", std::string(24, '\0')), {}, {"t.npy", "4 points", "holds 24 bytes"}},
        {"not_npy", "x.npy", "0 0 0\n", {}, {"x.npy", "not a NumPy"}},
        {"noise_input", "ok.txt", "0 0 0\n", {"--input", "noise"}, {"input.seeds", "input.type", "spots"}},
        {"with_surface", "ok.txt", "0 0 0\n", {"--surface", "speed"}, {"input.seeds", "input.surface"}},
    };
}

class SeedsBadFileTest : public SeedsTest, public ::testing::WithParamInterface<std::size_t>
{
};

TEST_P(SeedsBadFileTest, ExitsTwoNamingTheFileAndTheProblem)
{
    const BadSeeds c = badSeeds()[GetParam()];
    SCOPED_TRACE(c.name);
    if (!c.file.empty()) writeFile(c.file, c.bytes);
    std::vector<std::string> args{"bake", "--field", work("u.vdb"), "--out", work("o.vdb"), "--length", "4"};
    if (c.extra.empty() || c.extra[0] != "--input") args.insert(args.end(), {"--input", "spots"});
    if (!c.file.empty()) args.insert(args.end(), {"--seeds", c.file});
    args.insert(args.end(), c.extra.begin(), c.extra.end());
    const RunResult r = run(args);
    EXPECT_EQ(r.code, 2) << r.describe();
    for (const auto& part : c.expect) EXPECT_NE(r.err.find(part), std::string::npos) << "missing '" << part << "'\n" << r.describe();
    EXPECT_FALSE(fs::exists(work("o.vdb")));
}

INSTANTIATE_TEST_SUITE_P(Cases, SeedsBadFileTest, ::testing::Range<std::size_t>(0, badSeeds().size()),
                         [](const ::testing::TestParamInfo<std::size_t>& p) { return std::string(badSeeds()[p.param].name); });

} // namespace

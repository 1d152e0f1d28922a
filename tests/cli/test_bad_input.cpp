// The bad-input suite: each case gives `licvdb bake` one broken input and expects exit 2, a
// message on stderr that names the problem, no crash, and no file left behind (no output .vdb,
// no manifest, no temporary file). Cases cover the field formats (vdb, npy, vti, vtk, raw),
// field preparation, recipes and parameters. (tests/cli/test_cli.cpp has an older suite of
// 19 cases for .vdb fields; the cases here are new or exercise the new readers.)
#include "InputsHarness.h"

#include "vdbexport/io/AtomicWrite.h"

#include <lic/field/Presets.h>

#include <limits>
#include <set>

using namespace inputs_test;

namespace {

struct BadCase
{
    std::string name;
    /// Creates inputs in `w` and returns the licvdb arguments.
    std::function<std::vector<std::string>(const fs::path& w)> setup;
    std::vector<std::string> words; ///< stderr must contain each (case-insensitive)
};

/// A good 6x5x4 swirl .npy in `w`.
fs::path goodNpy(const fs::path& w, const std::string& name = "good.npy")
{
    writeBytes(w / name, npy("<f4", "(6, 5, 4, 3)", npyData(6, 5, 4, [](int i, int j, int k) { return swirl(i, j, k, 6, 5); })));
    return w / name;
}

/// A good .vdb with `velocity` (vec3s) and `temperature` (float).
fs::path goodVdb(const fs::path& w)
{
    const lic::PresetField f = lic::makePresetField("tabbed-jet", openvdb::Coord(12, 12, 16));
    openvdb::GridPtrVec grids{f.velocity};
    for (const auto& s : f.scalars) grids.push_back(s);
    vdbexport::writeVdbAtomic((w / "jet.vdb").string(), grids);
    return w / "jet.vdb";
}

std::string vtiAscii(const std::string& extent, const std::string& spacing, const std::string& values)
{
    return "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\">\n"
           "<ImageData WholeExtent=\"" + extent + "\" Origin=\"0 0 0\" Spacing=\"" + spacing + "\">\n<Piece Extent=\""
           + extent + "\">\n<PointData>\n<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"ascii\">\n"
           + values + "\n</DataArray>\n</PointData>\n</Piece>\n</ImageData>\n</VTKFile>\n";
}

/// "1 0 0.1 1 0 0.1 ..." for n voxels.
std::string ones(int n, const std::string& v = "1 0.5 0.1")
{
    std::string s;
    for (int i = 0; i < n; ++i) s += v + "\n";
    return s;
}

const std::vector<BadCase>& cases()
{
    static const std::vector<BadCase> all = {
        {"missing npy file", [](const fs::path& w) { return InputsTest::bakeArgs(w / "nosuch.npy", w / "out.vdb"); },
         {"nosuch.npy", "not found"}},
        {"field path is a directory (vti)",
         [](const fs::path& w) {
             fs::create_directories(w / "dir.vti");
             return InputsTest::bakeArgs(w / "dir.vti", w / "out.vdb");
         },
         {"dir.vti", "directory"}},
        {"empty npy file",
         [](const fs::path& w) {
             writeBytes(w / "empty.npy", "");
             return InputsTest::bakeArgs(w / "empty.npy", w / "out.vdb");
         },
         {"empty.npy", "empty"}},
        {"truncated VDB",
         [](const fs::path& w) {
             const fs::path v = goodVdb(w);
             const std::string bytes = readText(v);
             writeBytes(w / "cut.vdb", bytes.substr(0, bytes.size() * 2 / 3));
             fs::remove(v);
             return InputsTest::bakeArgs(w / "cut.vdb", w / "out.vdb");
         },
         {"cut.vdb", "truncated"}},
        {"VDB with no Vec3 grid (density and temperature only)",
         [](const fs::path& w) {
             openvdb::GridPtrVec grids;
             for (const char* n : {"density", "temperature"}) {
                 auto g = openvdb::FloatGrid::create(0.0f);
                 g->setName(n);
                 g->tree().setValueOn(openvdb::Coord(1, 2, 3), 1.0f);
                 grids.push_back(g);
             }
             vdbexport::writeVdbAtomic((w / "smoke.vdb").string(), grids);
             return InputsTest::bakeArgs(w / "smoke.vdb", w / "out.vdb");
         },
         {"no Vec3 grid", "density (float)"}},
        {"wrong grid name (vti array)",
         [](const fs::path& w) {
             writeBytes(w / "f.vti", vtiAscii("0 1 0 1 0 1", "1 1 1", ones(8)));
             return InputsTest::bakeArgs(w / "f.vti", w / "out.vdb", {"--grid", "speed"});
         },
         {"speed", "velocity (3 components)"}},
        {"float grid given as field",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodVdb(w), w / "out.vdb", {"--grid", "temperature"}); },
         {"temperature", "float grid", "Vec3"}},
        {"all-zero npy field",
         [](const fs::path& w) {
             writeBytes(w / "zero.npy", npy("<f4", "(4, 4, 4, 3)", std::string(4 * 4 * 4 * 3 * 4, '\0')));
             return InputsTest::bakeArgs(w / "zero.npy", w / "out.vdb");
         },
         {"zero"}},
        {"NaN in npy field",
         [](const fs::path& w) {
             std::string d = npyData(4, 4, 4, [](int i, int j, int k) {
                 return (i == 2 && j == 3 && k == 1) ? openvdb::Vec3s(std::numeric_limits<float>::quiet_NaN()) : openvdb::Vec3s(1, 0, 0);
             });
             writeBytes(w / "nan.npy", npy("<f4", "(4, 4, 4, 3)", d));
             return InputsTest::bakeArgs(w / "nan.npy", w / "out.vdb");
         },
         {"nan.npy", "1 NaN or infinite", "voxel (2, 3, 1)", "--nan-policy zero"}},
        {"Inf in vti field",
         [](const fs::path& w) {
             writeBytes(w / "inf.vti", vtiAscii("0 1 0 1 0 1", "1 1 1", ones(7) + "inf 0 0\n"));
             return InputsTest::bakeArgs(w / "inf.vti", w / "out.vdb");
         },
         {"inf.vti", "NaN or infinite", "voxel (1, 1, 1)"}},
        {"negative voxel size",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--voxel-size", "-0.5"}); },
         {"voxel_size", "> 0", "-0.5"}},
        {"zero voxel size in a vti file",
         [](const fs::path& w) {
             writeBytes(w / "flat.vti", vtiAscii("0 1 0 1 0 1", "1 0 1", ones(8)));
             return InputsTest::bakeArgs(w / "flat.vti", w / "out.vdb");
         },
         {"flat.vti", "spacing", "not positive"}},
        {"1-voxel field",
         [](const fs::path& w) {
             writeBytes(w / "one.npy", npy("<f4", "(1, 1, 1, 3)", npyData(1, 1, 1, [](int, int, int) { return openvdb::Vec3s(1, 0, 0); })));
             return InputsTest::bakeArgs(w / "one.npy", w / "out.vdb");
         },
         {"one.npy", "single active voxel"}},
        {"enormous dimensions in an npy header",
         [](const fs::path& w) {
             writeBytes(w / "huge.npy", npy("<f4", "(200000, 200000, 200000, 3)", std::string(96, '\0')));
             return InputsTest::bakeArgs(w / "huge.npy", w / "out.vdb");
         },
         {"huge.npy", "too large"}},
        {"enormous dimensions in a vti header",
         [](const fs::path& w) {
             writeBytes(w / "huge.vti", vtiAscii("0 999999 0 999999 0 999999", "1 1 1", ones(8)));
             return InputsTest::bakeArgs(w / "huge.vti", w / "out.vdb");
         },
         {"huge.vti", "too large"}},
        {"enormous dimensions in a legacy vtk header",
         [](const fs::path& w) {
             writeBytes(w / "huge.vtk", "# vtk DataFile Version 3.0\nx\nBINARY\nDATASET STRUCTURED_POINTS\n"
                                        "DIMENSIONS 3000000 3000000 3000000\nPOINT_DATA 27000000000000000000\n");
             return InputsTest::bakeArgs(w / "huge.vtk", w / "out.vdb");
         },
         {"huge.vtk", "too large"}},
        {"mismatched shape (raw)",
         [](const fs::path& w) {
             writeBytes(w / "f.raw", npyData(4, 4, 4, [](int, int, int) { return openvdb::Vec3s(1, 0, 0); }));
             return InputsTest::bakeArgs(w / "f.raw", w / "out.vdb", {"--shape", "4,4,5"});
         },
         {"f.raw", "--shape", "bytes"}},
        {"mismatched shape (vti values vs extent)",
         [](const fs::path& w) {
             writeBytes(w / "short.vti", vtiAscii("0 2 0 2 0 2", "1 1 1", ones(8)));
             return InputsTest::bakeArgs(w / "short.vti", w / "out.vdb");
         },
         {"short.vti", "mismatched shape"}},
        {"npy with an unsupported dtype",
         [](const fs::path& w) {
             writeBytes(w / "c.npy", npy("<c8", "(2, 2, 2, 3)", std::string(2 * 2 * 2 * 3 * 8, '\0')));
             return InputsTest::bakeArgs(w / "c.npy", w / "out.vdb");
         },
         {"c.npy", "dtype", "<c8"}},
        {"malformed JSON recipe (field section)",
         [](const fs::path& w) {
             writeBytes(w / "bad.json", "{\"field\": {\"crop\": [[0,0,0] [1,1,1]]}}");
             return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--recipe", (w / "bad.json").string()});
         },
         {"bad.json", "invalid JSON", "line 1"}},
        {"unknown recipe key in field",
         [](const fs::path& w) {
             writeBytes(w / "typo.json", "{\"field\": {\"nan_polcy\": \"zero\"}}");
             return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--recipe", (w / "typo.json").string()});
         },
         {"unknown key", "field.nan_polcy", "did you mean \"nan_policy\""}},
        {"negative length in a recipe",
         [](const fs::path& w) {
             writeBytes(w / "neg.json", "{\"lic\": {\"length\": -3}}");
             return std::vector<std::string>{"bake", "--field", goodNpy(w).string(), "--out", (w / "out.vdb").string(),
                                             "--recipe", (w / "neg.json").string()};
         },
         {"lic.length", "-3"}},
        {"step 0 in a recipe",
         [](const fs::path& w) {
             writeBytes(w / "step.json", "{\"lic\": {\"step\": 0}}");
             return std::vector<std::string>{"bake", "--field", goodNpy(w).string(), "--out", (w / "out.vdb").string(),
                                             "--recipe", (w / "step.json").string()};
         },
         {"lic.step", "> 0"}},
        {"decay >= 1",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--kernel", "exp", "--decay", "1"}); },
         {"lic.decay", "(0, 1)"}},
        {"frames 0 in a recipe",
         [](const fs::path& w) {
             writeBytes(w / "frames.json", "{\"animation\": {\"frames\": 0}}");
             return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--recipe", (w / "frames.json").string()});
         },
         {"animation.frames", "[1, 10000]"}},
        {"unwritable output path (parent is a file)",
         [](const fs::path& w) {
             writeBytes(w / "afile", "x");
             return InputsTest::bakeArgs(goodNpy(w), w / "afile" / "out.vdb");
         },
         {"afile"}},
        {"unknown extension without --format",
         [](const fs::path& w) {
             fs::copy_file(goodNpy(w), w / "field.dat2");
             return InputsTest::bakeArgs(w / "field.dat2", w / "out.vdb");
         },
         {"field.dat2", "--format"}},
        {"unknown --format",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--format", "hdf5"}); },
         {"field.format", "hdf5"}},
        {"raw without --shape",
         [](const fs::path& w) {
             writeBytes(w / "f.raw", npyData(2, 2, 2, [](int, int, int) { return openvdb::Vec3s(1, 0, 0); }));
             return InputsTest::bakeArgs(w / "f.raw", w / "out.vdb");
         },
         {"f.raw", "--shape"}},
        {"crop box outside the field",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--crop", "50,50,50,60,60,60"}); },
         {"crop box", "no voxel centre"}},
        {"--voxel-size on a .vdb field",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodVdb(w), w / "out.vdb", {"--voxel-size", "0.5"}); },
         {"voxel", ".vdb"}},
        {"--nan-policy with a bad value",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--nan-policy", "ignore"}); },
         {"field.nan_policy", "refuse", "zero"}},
        {"--origin with two numbers",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--origin", "1,2"}); },
         {"--origin", "X,Y,Z"}},
        {"recipe ROI without a range",
         [](const fs::path& w) {
             writeBytes(w / "roi.json", R"({"input": {"type": "spots"}, "roi": {"scalar": "speed"}})");
             return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--recipe", (w / "roi.json").string()});
         },
         {"roi.range", "required"}},
        {"--out is the input field",
         [](const fs::path& w) { return InputsTest::bakeArgs(goodVdb(w), goodVdb(w)); },
         {"overwrite", "input field", "--out"}},
        {"the manifest would replace the recipe",
         [](const fs::path& w) {
             writeBytes(w / "r.licvdb.json", R"({"lic": {"length": 4}})");
             return InputsTest::bakeArgs(goodNpy(w), w / "r.vdb", {"--recipe", (w / "r.licvdb.json").string()});
         },
         {"overwrite", "recipe", "r.licvdb.json"}},
        {"a lic key the engine does not read (--min-hits with splat)",
         [](const fs::path& w) {
             return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--input", "spots", "--min-hits", "3"});
         },
         {"lic.min_hits", "\"splat\" engine", "does not use it", "it reads lic.kernel", "lic.brick", ": fast"}},
        {"lic.decay with the box kernel in a recipe",
         [](const fs::path& w) {
             writeBytes(w / "decay.json", R"({"lic": {"engine": "naive", "decay": 0.8}})");
             return InputsTest::bakeArgs(goodNpy(w), w / "out.vdb", {"--recipe", (w / "decay.json").string()});
         },
         {"lic.decay", "\"box\" kernel", "lic.kernel \"exp\""}},
    };
    return all;
}

class BadInputTest : public InputsTest, public ::testing::WithParamInterface<std::size_t>
{
};

TEST_P(BadInputTest, ExitsTwoNamesProblemWritesNothing)
{
    const BadCase& c = cases().at(GetParam());
    SCOPED_TRACE(c.name);
    const RunResult r = expectRefusedWritingNothing(c.setup(work()), c.words);
    if (std::getenv("LICVDB_TEST_SHOW_ERRORS")) std::cout << c.name << ":\n" << r.err;
}

INSTANTIATE_TEST_SUITE_P(Cases, BadInputTest, ::testing::Range<std::size_t>(0, cases().size()),
                         [](const ::testing::TestParamInfo<std::size_t>& p) {
                             std::string n;
                             for (char ch : cases()[p.param].name) n += std::isalnum(static_cast<unsigned char>(ch)) ? ch : '_';
                             return std::to_string(p.param) + "_" + n;
                         });

// A bake never replaces its own inputs: the field and the recipe keep their bytes.
TEST_F(InputsTest, BakeDoesNotOverwriteItsInputs)
{
    const fs::path w = work();
    const fs::path field = goodVdb(w);
    const fs::path recipe = w / "r.licvdb.json"; // the manifest name of r.vdb
    writeBytes(recipe, R"({"lic": {"length": 4}})");
    const std::string fieldBytes = readText(field), recipeBytes = readText(recipe);
    for (const auto& args : {bakeArgs(field, field), bakeArgs(field, w / "r.vdb", {"--recipe", recipe.string()}),
                             bakeArgs(field, w / "./r.vdb", {"--recipe", recipe.string(), "--frames", "2"})}) {
        const RunResult r = run(args);
        EXPECT_EQ(r.code, 2) << r.describe();
        EXPECT_EQ(readText(field), fieldBytes);
        EXPECT_EQ(readText(recipe), recipeBytes);
    }
    // A different output name is fine.
    const RunResult ok = run(bakeArgs(field, w / "lic.vdb", {"--recipe", recipe.string()}));
    EXPECT_EQ(ok.code, 0) << ok.describe();
    EXPECT_EQ(readText(recipe), recipeBytes);
}

// A recipe run from another directory: its relative paths are taken from the working directory,
// and the message says which one (the field and the output directory are both reported so).
TEST_F(InputsTest, RelativePathsNameTheWorkingDirectory)
{
    const fs::path w = work();
    fs::create_directories(w / "elsewhere");
    writeBytes(w / "r.json", R"({"field": {"path": "out/f.vdb"}, "output": {"path": "out/lic.vdb"}})");
    RunResult r = runCommand("cd elsewhere && " + cli_test::licvdbCommand({"bake", "--recipe", "../r.json"}));
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_NE(r.err.find("field file \"out/f.vdb\" not found"), std::string::npos) << r.describe();
    EXPECT_NE(r.err.find("working directory " + (w / "elsewhere").string()), std::string::npos) << r.describe();
    goodVdb(w);
    r = runCommand(cli_test::licvdbCommand({"bake", "--recipe", "r.json", "--field", "jet.vdb"}));
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_NE(r.err.find("output directory \"out\" does not exist"), std::string::npos) << r.describe();
    EXPECT_NE(r.err.find("working directory " + w.string()), std::string::npos) << r.describe();
}

// A recipe named like its output (flow.json for flow.vdb) is fine: the manifest is
// flow.licvdb.json (it was flow.json, and such bakes were refused), for a still and for a loop.
TEST_F(InputsTest, RecipeNamedLikeTheOutputIsKept)
{
    const fs::path w = work();
    const fs::path field = goodVdb(w);
    writeBytes(w / "flow.json", R"({"lic": {"length": 4}})");
    const std::string recipeBytes = readText(w / "flow.json");
    for (const auto& extra : {std::vector<std::string>{}, std::vector<std::string>{"--frames", "2"}}) {
        std::vector<std::string> flags{"--recipe", (w / "flow.json").string()};
        flags.insert(flags.end(), extra.begin(), extra.end());
        const RunResult r = run(bakeArgs(field, w / "flow.vdb", flags));
        EXPECT_EQ(r.code, 0) << r.describe();
        EXPECT_EQ(readText(w / "flow.json"), recipeBytes);
        EXPECT_TRUE(fs::is_regular_file(w / "flow.licvdb.json")) << r.describe();
    }
}

TEST(BadInputSuite, CoversAtLeastTwentyCases) { EXPECT_GE(cases().size(), 20u); }

} // namespace

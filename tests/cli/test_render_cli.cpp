// End-to-end tests of `licvdb render`: the built binary (LICVDB_EXE) renders small bakes made by
// `licvdb field` + `licvdb bake` once per suite; each test runs in a fresh directory and checks
// exit codes, messages, the --json summary and the images written (read back with OIIO).
#include <gtest/gtest.h>

#include "CliRun.h"
#include "../unit/TempDirSuite.h"
#include "vdbexport/io/ImageIO.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using cli_test::lower;
using cli_test::readText;
using cli_test::RunResult;

/// Run licvdb with `args` in `dir`, capturing stdout/stderr into `logs`.
RunResult runIn(const fs::path& dir, const fs::path& logs, const std::vector<std::string>& args)
{
    return cli_test::runLicvdb(dir, logs, args);
}

class RenderCli : public lictest::TempDirSuite<RenderCli>
{
protected:
    // Shared inputs: a 12³ abc field, a bake with tangent and colour, a 2-frame loop.
    static void SetUpTestSuite()
    {
        makeSuiteDir("test_render_cli", "logs");
        auto must = [](const RunResult& r) {
            if (r.code != 0) {
                std::cerr << r.describe();
                std::abort();
            }
        };
        must(runIn(sDir, sDir / "logs", {"field", "abc", "--res", "12,12,12", "--out", "abc.vdb", "--quiet"}));
        must(runIn(sDir, sDir / "logs",
                   {"bake", "--field", "abc.vdb", "--out", "lic.vdb", "--length", "4", "--write-tangent", "--color",
                    "speed", "--quiet"}));
        must(runIn(sDir, sDir / "logs",
                   {"bake", "--field", "abc.vdb", "--out", "loop.vdb", "--length", "4", "--frames", "2", "--quiet"}));
    }
    void SetUp() override
    {
        static std::atomic<int> counter{0};
        mDir = sDir / ("t" + std::to_string(counter++));
        fs::create_directories(mDir);
    }

    RunResult run(const std::vector<std::string>& args) { return runIn(mDir, sDir / "logs", args); }
    static std::string shared(const std::string& name) { return (sDir / name).string(); }
    fs::path out(const std::string& name) const { return mDir / name; }
    std::set<std::string> files() const
    {
        std::set<std::string> s;
        for (const auto& e : fs::directory_iterator(mDir)) s.insert(e.path().filename().string());
        return s;
    }

    fs::path mDir;
};

double sum(const lic::Image& img)
{
    double s = 0;
    for (std::size_t i = 0; i < img.rgba.size(); i += 4) s += img.rgba[i] + img.rgba[i + 1] + img.rgba[i + 2];
    return s;
}

} // namespace

TEST_F(RenderCli, PngWithJsonSummary)
{
    const RunResult r = run({"render", shared("lic.vdb"), "--out", "a.png", "--size", "64,48", "--json", "--threads", "2"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json j = json::parse(r.out);
    ASSERT_EQ(j["files"].size(), 1u);
    EXPECT_EQ(j["files"][0], "a.png");
    const json& c = j["camera"];
    for (const char* k : {"position", "forward", "up", "right", "target", "fov_y_degrees", "fov_x_degrees", "distance"})
        EXPECT_TRUE(c.contains(k)) << k << "\n" << r.out;
    EXPECT_EQ(c["projection"], "perspective");
    EXPECT_EQ(c["image_size"], json::array({64, 48}));
    EXPECT_EQ(c["forward"], json::array({0.0, 1.0, 0.0})) << "default front view";
    EXPECT_TRUE(c["blender"].contains("matrix_world"));
    EXPECT_TRUE(j["illuminated"].get<bool>()) << "the bake has a tangent grid";
    EXPECT_TRUE(j["colored"].get<bool>()) << "the bake has a color grid";
    EXPECT_FALSE(j["halos"].get<bool>()) << "a noise bake has no halo grid";
    EXPECT_GT(j["seconds"]["render"].get<double>(), 0.0);
    const lic::Image img = vdbexport::readImage(out("a.png").string());
    EXPECT_EQ(img.width, 64);
    EXPECT_EQ(img.height, 48);
    EXPECT_GT(sum(img), 10.0) << "the image must show something";
    // Without --json: a message on stderr, nothing on stdout.
    const RunResult q = run({"render", shared("lic.vdb"), "--out", "b.png", "--size", "16,16"});
    ASSERT_EQ(q.code, 0) << q.describe();
    EXPECT_TRUE(q.out.empty());
    EXPECT_NE(q.err.find("b.png"), std::string::npos) << q.describe();
}

TEST_F(RenderCli, ExrOrthographicViewsAndThreadDeterminism)
{
    RunResult r = run({"render", shared("lic.vdb"), "--out", "t1.exr", "--size", "40,30", "--view", "top", "--ortho",
                       "--threads", "1", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json j = json::parse(r.out);
    EXPECT_EQ(j["camera"]["projection"], "orthographic");
    EXPECT_TRUE(j["camera"].contains("ortho_width"));
    EXPECT_EQ(j["camera"]["forward"], json::array({0.0, 0.0, -1.0}));
    r = run({"render", shared("lic.vdb"), "--out", "t2.exr", "--size", "40,30", "--view", "top", "--ortho", "--threads", "2"});
    ASSERT_EQ(r.code, 0) << r.describe();
    std::string cs;
    const lic::Image a = vdbexport::readImage(out("t1.exr").string(), &cs), b = vdbexport::readImage(out("t2.exr").string());
    EXPECT_EQ(cs, "lin_rec709_scene"); // OIIO 2.4 reads "Linear", 3.x "lin_rec709_scene"
    ASSERT_EQ(a.rgba.size(), b.rgba.size());
    EXPECT_EQ(a.rgba, b.rgba) << "bit-identical for 1 and 2 threads";
    EXPECT_GT(sum(a), 1.0);
    // Azimuth/elevation override the view.
    r = run({"render", shared("lic.vdb"), "--out", "c.exr", "--size", "8,8", "--view", "right", "--elevation", "30", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json k = json::parse(r.out);
    EXPECT_DOUBLE_EQ(k["camera"]["azimuth_degrees"].get<double>(), 90.0);
    EXPECT_DOUBLE_EQ(k["camera"]["elevation_degrees"].get<double>(), 30.0);
}

TEST_F(RenderCli, StereoSideBySideAndAnaglyph)
{
    RunResult r = run({"render", shared("lic.vdb"), "--out", "s.png", "--size", "32,24", "--stereo", "sbs", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json j = json::parse(r.out);
    EXPECT_EQ(j["image_size"], json::array({64, 24}));
    EXPECT_TRUE(j["stereo"]["left"].contains("position"));
    lic::Image img = vdbexport::readImage(out("s.png").string());
    EXPECT_EQ(img.width, 64);
    EXPECT_EQ(img.height, 24);
    r = run({"render", shared("lic.vdb"), "--out", "a.png", "--size", "32,24", "--stereo", "anaglyph"});
    ASSERT_EQ(r.code, 0) << r.describe();
    img = vdbexport::readImage(out("a.png").string());
    EXPECT_EQ(img.width, 32);
    EXPECT_EQ(img.height, 24);
}

TEST_F(RenderCli, SequencesManifestsAndGif)
{
    RunResult r = run({"render", shared("loop_0001.vdb"), "--frames", "2", "--out", "seq.png", "--size", "16,12", "--gif"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(files(), (std::set<std::string>{"seq_0001.png", "seq_0002.png", "seq.gif"}));
    r = run({"render", shared("loop.licvdb.json"), "--out", "m.exr", "--size", "16,12", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json j = json::parse(r.out);
    EXPECT_EQ(j["frames"], 2);
    EXPECT_TRUE(fs::exists(out("m_0001.exr")));
    EXPECT_TRUE(fs::exists(out("m_0002.exr")));
    // A manifest under its old name (OUT.json, bakes made before the rename) reads the same.
    fs::copy_file(shared("loop.licvdb.json"), out("old.json"));
    fs::copy_file(shared("loop_0001.vdb"), out("loop_0001.vdb"));
    fs::copy_file(shared("loop_0002.vdb"), out("loop_0002.vdb"));
    r = run({"render", out("old.json").string(), "--out", "o.exr", "--size", "16,12", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(json::parse(r.out)["frames"], 2);
    EXPECT_EQ(vdbexport::readImage(out("o_0002.exr").string()).rgba, vdbexport::readImage(out("m_0002.exr").string()).rgba);
    // The two frames of a loop differ.
    EXPECT_NE(vdbexport::readImage(out("m_0001.exr").string()).rgba, vdbexport::readImage(out("m_0002.exr").string()).rgba);
    // A missing frame is an input error and writes nothing.
    r = run({"render", shared("loop_0001.vdb"), "--frames", "3", "--out", "x.png", "--size", "8,8"});
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_NE(r.err.find("loop_0003.vdb"), std::string::npos) << r.describe();
    EXPECT_FALSE(fs::exists(out("x_0001.png")));
}

TEST_F(RenderCli, BadInputExitsTwoWithAMessageAndNoFile)
{
    std::ofstream(out("text.vdb")) << "this is not a vdb file\n";
    struct Case
    {
        std::vector<std::string> args;
        std::string expect; // lower-case substring of stderr
    };
    const std::vector<Case> cases = {
        {{"render", "missing.vdb", "--out", "o.png"}, "missing.vdb"},
        {{"render", "text.vdb", "--out", "o.png"}, "vdb"},
        {{"render", shared("abc.vdb"), "--out", "o.png"}, "density"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--size", "12x3"}, "--size"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--size", "0,10"}, "--size"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--size", "1,2,3"}, "--size"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--view", "side"}, "side"},
        {{"render", shared("lic.vdb"), "--out", "nodir/o.png"}, "does not exist"},
        {{"render", shared("lic.vdb"), "--out", "o.bmpx"}, "extension"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--halos", "maybe"}, "--halos"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--light", "1,2"}, "--light"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--stereo", "3d"}, "stereo"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--colormap", "jet"}, "jet"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--density-scale", "-1"}, "density scale"},
        {{"render", shared("lic.vdb"), "--out", "o.png", "--view-transform", "agx"}, "agx"},
    };
    for (const auto& c : cases) {
        const RunResult r = run(c.args);
        EXPECT_EQ(r.code, 2) << r.describe();
        EXPECT_NE(lower(r.err).find(lower(c.expect)), std::string::npos) << "expected \"" << c.expect << "\"\n" << r.describe();
        EXPECT_EQ(files(), (std::set<std::string>{"text.vdb"})) << r.describe();
    }
    // The file without density names the grids it has.
    const RunResult r = run({"render", shared("abc.vdb"), "--out", "o.png"});
    EXPECT_NE(r.err.find("velocity"), std::string::npos) << r.describe();
}

// OpenImageIO and OpenColorIO are a module licvdb loads on first use (ImageModuleApi.h): licvdb
// itself does not link them (they cost every start ~0.3 s), a bake runs without the module, and
// an image command without it fails with one message naming where it looked, exit 1, no file.
TEST_F(RenderCli, TheImageLibrariesAreLoadedOnlyByImageCommands)
{
    const RunResult libs = cli_test::runShell(mDir, sDir / "logs", "ldd " + cli_test::shellQuote(LICVDB_EXE));
    ASSERT_EQ(libs.code, 0) << libs.describe();
    EXPECT_NE(libs.out.find("libopenvdb"), std::string::npos) << libs.out;
    EXPECT_EQ(libs.out.find("libOpenImageIO"), std::string::npos) << libs.out;
    EXPECT_EQ(libs.out.find("libOpenColorIO"), std::string::npos) << libs.out;

    const auto withModule = [&](const std::string& module, const std::vector<std::string>& args) {
        return cli_test::runShell(mDir, sDir / "logs",
                                  "LICVDB_IMAGE_MODULE=" + cli_test::shellQuote(module) + " " + cli_test::licvdbCommand(args));
    };
    const std::string missing = (mDir / "nowhere" / "licvdb-image.so").string();
    RunResult r = withModule(missing, {"render", shared("lic.vdb"), "--out", "o.png", "--size", "16,16"});
    EXPECT_EQ(r.code, 1) << r.describe();
    EXPECT_NE(r.err.find("image module"), std::string::npos) << r.describe();
    EXPECT_NE(r.err.find(missing), std::string::npos) << r.describe();
    EXPECT_TRUE(files().empty()) << r.describe();

    std::ofstream(out("fake.so")) << "not a shared object\n";
    r = withModule(out("fake.so").string(), {"render", shared("lic.vdb"), "--out", "o.png", "--size", "16,16"});
    EXPECT_EQ(r.code, 1) << r.describe();
    EXPECT_NE(r.err.find("cannot be loaded"), std::string::npos) << r.describe();
    EXPECT_EQ(files(), (std::set<std::string>{"fake.so"})) << r.describe();

    r = withModule(missing, {"bake", "--field", shared("abc.vdb"), "--out", "b.vdb", "--length", "4", "--quiet"});
    EXPECT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(fs::is_regular_file(out("b.vdb"))) << r.describe();
    // With the module found, the same render works.
    r = run({"render", out("b.vdb").string(), "--out", "o.png", "--size", "16,16"});
    EXPECT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(vdbexport::readImage(out("o.png").string()).width, 16);
}

TEST_F(RenderCli, HelpListsRender)
{
    RunResult r = run({"help", "render"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_NE(r.out.find("--halos"), std::string::npos);
    EXPECT_NE(r.out.find("--stereo"), std::string::npos);
    r = run({"help"});
    EXPECT_NE(r.out.find("render"), std::string::npos);
}

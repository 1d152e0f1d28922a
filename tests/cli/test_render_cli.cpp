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
#include <cmath>
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
        // A small tabbed jet: a dense noise bake and a spot bake of it (48 x 48 x 72 voxels).
        must(runIn(sDir, sDir / "logs", {"field", "tabbed-jet", "--res", "24,24,36", "--out", "jet.vdb", "--quiet"}));
        must(runIn(sDir, sDir / "logs", {"bake", "--field", "jet.vdb", "--out", "jet_noise.vdb", "--input", "noise", "--quiet"}));
        must(runIn(sDir, sDir / "logs",
                   {"bake", "--field", "jet.vdb", "--out", "jet_spots.vdb", "--input", "spots", "--spacing", "8", "--quiet"}));
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

/// Luminance statistics of an image's pixels where `footprint` (the same size) has alpha > ½:
/// the coefficient of variation (std / mean) and the fraction darker than half the mean.
struct Contrast
{
    double variation = 0, darkFraction = 0;
    std::size_t pixels = 0;
};

Contrast contrastOver(const lic::Image& img, const lic::Image& footprint)
{
    std::vector<double> lum;
    for (std::size_t i = 0; i + 3 < img.rgba.size(); i += 4)
        if (footprint.rgba[i + 3] > 0.5f)
            lum.push_back(0.2126 * img.rgba[i] + 0.7152 * img.rgba[i + 1] + 0.0722 * img.rgba[i + 2]);
    Contrast c;
    c.pixels = lum.size();
    if (lum.empty()) return c;
    double sum = 0, sq = 0;
    for (const double v : lum) sum += v;
    const double mean = sum / double(lum.size());
    std::size_t dark = 0;
    for (const double v : lum) {
        sq += (v - mean) * (v - mean);
        dark += v < 0.5 * mean;
    }
    c.variation = mean > 0 ? std::sqrt(sq / double(lum.size())) / mean : 0.0;
    c.darkFraction = double(dark) / double(lum.size());
    return c;
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

// Issue 54 item 6: a dense noise bake (density ≈ 0.5 everywhere) renders through the default
// window 0,1 as an opaque slab; by default the renderer windows it on its density percentiles.
TEST_F(RenderCli, ADenseNoiseBakeGetsAnAutomaticDensityWindowThatShowsStreaks)
{
    const std::vector<std::string> look = {"--size", "96,96", "--view", "right", "--threads", "2", "--json"};
    auto render = [&](const std::string& image, std::vector<std::string> extra) {
        std::vector<std::string> args = {"render", shared("jet_noise.vdb"), "--out", image};
        args.insert(args.end(), look.begin(), look.end());
        args.insert(args.end(), extra.begin(), extra.end());
        const RunResult r = run(args);
        EXPECT_EQ(r.code, 0) << r.describe();
        return r.code == 0 ? json::parse(r.out)["settings"] : json();
    };
    const json byDefault = render("default.exr", {});
    ASSERT_TRUE(byDefault.is_object());
    EXPECT_TRUE(byDefault["density_range_auto"].get<bool>()) << byDefault.dump();
    const double lo = byDefault["density_range"][0], hi = byDefault["density_range"][1];
    // The stretched noise is ~N(0.5, 0.2): its 90th percentile is ~0.76, its 99.9th the clip at 1.
    EXPECT_GT(lo, 0.65) << byDefault.dump();
    EXPECT_LT(lo, 0.85) << byDefault.dump();
    EXPECT_GT(hi, lo);
    EXPECT_LE(hi, 1.0);
    EXPECT_EQ(byDefault["density_range_percentiles"], json::array({90.0, 99.9}));
    const json fixed = render("fixed.exr", {"--density-range", "0,1"});
    EXPECT_FALSE(fixed["density_range_auto"].get<bool>());
    EXPECT_EQ(fixed["density_range"], json::array({0.0, 1.0}));
    // `auto` is the default's window and image; the same file gives the same window every time.
    const json forced = render("auto.exr", {"--density-range", "auto"});
    EXPECT_TRUE(forced["density_range_auto"].get<bool>());
    EXPECT_EQ(forced["density_range"], byDefault["density_range"]);
    const lic::Image autoImg = vdbexport::readImage(out("default.exr").string());
    EXPECT_EQ(vdbexport::readImage(out("auto.exr").string()).rgba, autoImg.rgba);

    // The slab against the streaks, over the pixels the slab covers.
    const lic::Image slab = vdbexport::readImage(out("fixed.exr").string());
    const Contrast flat = contrastOver(slab, slab), streaks = contrastOver(autoImg, slab);
    ASSERT_GT(flat.pixels, 1000u) << "the bake must fill a good part of the frame";
    // Measured: variation 0.13 and no dark pixel for 0,1; 0.76 and 35% dark pixels with the window.
    EXPECT_LT(flat.variation, 0.25) << "0,1: an almost uniform slab";
    EXPECT_LT(flat.darkFraction, 0.02);
    EXPECT_GT(streaks.variation, 3.0 * flat.variation) << flat.variation << " vs " << streaks.variation;
    EXPECT_GT(streaks.darkFraction, 0.15) << "gaps between the streaks";

    // Without --json, one line names the window.
    const RunResult r = run({"render", shared("jet_noise.vdb"), "--out", "p.png", "--size", "16,16"});
    ASSERT_EQ(r.code, 0) << r.describe();
    std::ostringstream window;
    window << "density range " << lo << "," << hi << " (auto: the 90th to 99.9th percentile of the density";
    EXPECT_NE(r.err.find(window.str()), std::string::npos) << window.str() << "\n" << r.describe();
    const RunResult quiet = run({"render", shared("jet_noise.vdb"), "--out", "q.png", "--size", "16,16", "--quiet"});
    ASSERT_EQ(quiet.code, 0) << quiet.describe();
    EXPECT_TRUE(quiet.err.empty()) << quiet.describe();
}

TEST_F(RenderCli, ASpotBakeKeepsTheFullDensityWindowUnlessAutoIsAsked)
{
    RunResult r = run({"render", shared("jet_spots.vdb"), "--out", "default.exr", "--size", "64,64", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    json s = json::parse(r.out)["settings"];
    EXPECT_FALSE(s["density_range_auto"].get<bool>());
    EXPECT_EQ(s["density_range"], json::array({0.0, 1.0}));
    r = run({"render", shared("jet_spots.vdb"), "--out", "fixed.exr", "--size", "64,64"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(r.err.find("density range"), std::string::npos) << r.describe();
    EXPECT_EQ(vdbexport::readImage(out("default.exr").string()).rgba, vdbexport::readImage(out("fixed.exr").string()).rgba);
    // `auto` forces the automatic window on any bake.
    r = run({"render", shared("jet_spots.vdb"), "--out", "auto.exr", "--size", "64,64", "--density-range", "auto", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    s = json::parse(r.out)["settings"];
    EXPECT_TRUE(s["density_range_auto"].get<bool>());
    // Lines clamp at 1 and cover more than a tenth of the voxels > 0 of this dense spot bake: the
    // 90th and 99.9th percentiles are both 1 and leave no window; it is 0 to the largest density.
    EXPECT_EQ(s["density_range"], json::array({0.0, 1.0}));
    EXPECT_TRUE(s["density_range_percentiles"].is_null());
    r = run({"render", shared("jet_spots.vdb"), "--out", "auto.exr", "--size", "16,16", "--density-range", "auto"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_NE(r.err.find("density range 0,1 (auto: the percentiles of the density leave no window"), std::string::npos) << r.describe();
    // A sparser spot bake: the percentiles keep the line cores.
    r = run({"bake", "--field", shared("jet.vdb"), "--out", "sparse.vdb", "--input", "spots", "--spacing", "16", "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    r = run({"render", "sparse.vdb", "--out", "s.exr", "--size", "16,16", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(json::parse(r.out)["settings"]["density_range"], json::array({0.0, 1.0}));
    r = run({"render", "sparse.vdb", "--out", "s.exr", "--size", "16,16", "--density-range", "auto", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    s = json::parse(r.out)["settings"];
    EXPECT_GT(s["density_range"][0].get<double>(), 0.5) << s.dump();
    EXPECT_EQ(s["density_range_percentiles"], json::array({90.0, 99.9}));
    // LO,HI is taken as given, also for a noise bake.
    r = run({"render", shared("jet_noise.vdb"), "--out", "n.exr", "--size", "16,16", "--density-range", "0.6,0.9", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    s = json::parse(r.out)["settings"];
    EXPECT_FALSE(s["density_range_auto"].get<bool>());
    EXPECT_EQ(s["density_range"], json::array({0.6, 0.9}));
}

TEST_F(RenderCli, ABadDensityRangeNamesLoHiAndAuto)
{
    for (const std::string bad : {"automatic", "0.5", "0.7,0.2", "-1,1", "auto,1"}) {
        const RunResult r = run({"render", shared("jet_noise.vdb"), "--out", "o.png", "--density-range", bad});
        EXPECT_EQ(r.code, 2) << r.describe();
        EXPECT_NE(r.err.find("--density-range \"" + bad + "\""), std::string::npos) << r.describe();
        EXPECT_NE(r.err.find("LO,HI with 0 <= LO < HI, or auto"), std::string::npos) << r.describe();
        EXPECT_TRUE(files().empty()) << r.describe();
    }
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

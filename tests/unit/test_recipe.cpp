// Recipe parsing, validation, round trip; TerminalProgress output and timings.
#include "TempDirSuite.h"

#include <vdbexport/bake/Recipe.h>
#include <vdbexport/cli/TerminalProgress.h>

#include <lic/util/Error.h>

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>

#include <unistd.h>

using nlohmann::json;
using vdbexport::Recipe;

namespace {

// The example recipe of the project's design card ("Public contract"; docs/recipe.md).
const char* kDesignExample = R"({ "field":  {"path": "jet.vdb", "grid": "velocity"},
  "output": {"path": "out.vdb", "upsample": 2, "write_input": false, "write_series": false},
  "input":  {"type": "spots", "distribution": "poisson", "spacing": 6, "jitter": 0.25,
             "radii": [1.0, 1.5, 2.0], "halo_scale": 2.0, "seed": 7,
             "surface": null},
  "roi":    {"scalar": "speed", "range": [0.3, 1.0], "mode": "pre"},
  "lic":    {"engine": "fast", "kernel": "exp", "length": 20, "step": 0.5, "decay": 0.9,
             "integrator": "rk4"},
  "width":  {"scalar": "speed", "invert": true},
  "color":  {"scalar": "vorticity", "colormap": "heated-object", "range": "auto"},
  "animation": {"frames": 24},
  "threads": 0 })";

/// The message of the lic::InputError thrown by `f`, or a test failure if none is thrown.
std::string inputError(const std::function<void()>& f)
{
    try {
        f();
    } catch (const lic::InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected lic::InputError, got another exception: " << e.what();
        return "";
    }
    ADD_FAILURE() << "expected lic::InputError, nothing was thrown";
    return "";
}

/// The error of fromJson() on the defaults patched with `patch` (a JSON merge patch).
std::string parseError(const std::string& patch)
{
    json j = Recipe{}.toJson();
    j.merge_patch(json::parse(patch));
    return inputError([&] { Recipe::fromJson(j); });
}

/// The error of validate() on the defaults patched with `patch`.
std::string validateError(const std::string& patch)
{
    json j = Recipe{}.toJson();
    j.merge_patch(json::parse(patch));
    const Recipe r = Recipe::fromJson(j);
    return inputError([&] { r.validate(); });
}

#define EXPECT_CONTAINS(haystack, needle)                                                          \
    EXPECT_NE(std::string(haystack).find(needle), std::string::npos)                              \
        << "message: \"" << (haystack) << "\"\nexpected to contain: \"" << (needle) << "\""

std::string readAll(FILE* f)
{
    std::fflush(f);
    std::rewind(f);
    std::string s;
    char buf[256];
    while (std::size_t n = std::fread(buf, 1, sizeof(buf), f)) s.append(buf, n);
    return s;
}

} // namespace

// ---- defaults and round trip ------------------------------------------------------------

TEST(Recipe, DefaultsAreValidAndResolvedJsonHasEveryKey)
{
    const Recipe r;
    EXPECT_NO_THROW(r.validate());
    const json j = r.toJson();
    for (const char* key : {"field", "output", "input", "roi", "lic", "width", "color", "animation", "threads"}) {
        EXPECT_TRUE(j.contains(key)) << key;
    }
    EXPECT_TRUE(j["roi"].is_null());
    EXPECT_TRUE(j["width"].is_null());
    EXPECT_TRUE(j["color"].is_null());
    EXPECT_TRUE(j["input"]["surface"].is_null());
    EXPECT_EQ(j["input"]["seeds"], ""); // no seeds file: the distribution places the spots
    EXPECT_EQ(j["output"]["upsample"], 2);
    EXPECT_EQ(j["output"]["write_tangent"], false);
    EXPECT_EQ(j["output"]["half"], false);
    EXPECT_EQ(j["output"]["contrast"], "stretch");
    EXPECT_EQ(j["input"]["halo_scale"], 2.0);
    EXPECT_EQ(j["input"]["seed"], 1);
    EXPECT_EQ(j["lic"]["min_hits"], 2);
    EXPECT_EQ(j["lic"]["tolerance"], 1e-3);
    EXPECT_EQ(j["lic"]["engine"], "auto"); // resolved by the bake: splat for spots, fast for noise
    EXPECT_EQ(j["animation"]["frames"], 1);
}

TEST(Recipe, DefaultsRoundTrip)
{
    const Recipe r;
    const Recipe back = Recipe::fromJson(r.toJson());
    EXPECT_EQ(back, r);
    EXPECT_EQ(back.toJson(), r.toJson());
    EXPECT_EQ(Recipe::fromJson(json::object()), r); // {} = all defaults
}

TEST(Recipe, FullRecipeRoundTrip)
{
    Recipe r = vdbexport::parseRecipe(kDesignExample);
    r.input.surface = vdbexport::SurfaceSpec{"speed", 0.5};
    r.width->range = std::array<double, 2>{0.1, 0.9};
    r.color->range = std::array<double, 2>{-2.0, 3.5};
    r.input.seed = 0xFFFFFFFFFFFFFFFFull;
    r.lic.tolerance = 1e-7;
    const json j = r.toJson();
    Recipe seeded = Recipe::fromJson(json{{"input", {{"type", "spots"}, {"seeds", "cache/points.npy"}}}});
    EXPECT_EQ(seeded.input.seeds, "cache/points.npy");
    EXPECT_EQ(Recipe::fromJson(seeded.toJson()), seeded);
    const Recipe back = Recipe::fromJson(json::parse(j.dump()));
    EXPECT_EQ(back, r);
    EXPECT_EQ(back.toJson(), j);
}

// ---- the design card example --------------------------------------------------------------

TEST(Recipe, DesignExampleParses)
{
    const Recipe r = vdbexport::parseRecipe(kDesignExample);
    EXPECT_EQ(r.field.path, "jet.vdb");
    EXPECT_EQ(r.field.grid, "velocity");
    EXPECT_EQ(r.output.path, "out.vdb");
    EXPECT_EQ(r.output.upsample, 2);
    EXPECT_FALSE(r.output.writes(lic::OutputGrid::Input));
    EXPECT_FALSE(r.output.writes(lic::OutputGrid::LevelLines));
    EXPECT_EQ(r.input.type, "spots");
    EXPECT_EQ(r.input.distribution, "poisson");
    EXPECT_EQ(r.input.spacing, 6);
    EXPECT_EQ(r.input.jitter, 0.25);
    EXPECT_EQ(r.input.radii, (std::vector<double>{1.0, 1.5, 2.0}));
    EXPECT_EQ(r.input.haloScale, 2.0);
    EXPECT_EQ(r.input.seed, 7u);
    EXPECT_FALSE(r.input.surface.has_value());
    ASSERT_TRUE(r.roi.has_value());
    EXPECT_EQ(r.roi->scalar, "speed");
    EXPECT_EQ(r.roi->range, (std::array<double, 2>{0.3, 1.0}));
    EXPECT_EQ(r.roi->mode, "pre");
    EXPECT_EQ(r.lic.engine, "fast");
    EXPECT_EQ(r.lic.kernel, "exp");
    EXPECT_EQ(r.lic.length, 20);
    EXPECT_EQ(r.lic.step, 0.5);
    EXPECT_EQ(r.lic.decay, 0.9);
    EXPECT_EQ(r.lic.integrator, "rk4");
    EXPECT_EQ(r.lic.minHits, 2); // absent: default
    ASSERT_TRUE(r.width.has_value());
    EXPECT_EQ(r.width->scalar, "speed");
    EXPECT_TRUE(r.width->invert);
    EXPECT_FALSE(r.width->range.has_value());
    ASSERT_TRUE(r.color.has_value());
    EXPECT_EQ(r.color->scalar, "vorticity");
    EXPECT_EQ(r.color->colormap, "heated-object");
    EXPECT_FALSE(r.color->range.has_value());
    EXPECT_EQ(r.animation.frames, 24);
    EXPECT_EQ(r.threads, 0);
}

TEST(Recipe, PartialRecipeMergesOntoDefaults)
{
    const Recipe r = Recipe::fromJson(json::parse(R"({"lic": {"length": 40}, "roi": {"scalar": "speed"}})"));
    EXPECT_EQ(r.lic.length, 40);
    EXPECT_EQ(r.lic.step, 0.5);
    EXPECT_EQ(r.lic.engine, "auto");
    ASSERT_TRUE(r.roi.has_value());
    EXPECT_EQ(r.roi->range, (std::array<double, 2>{0, 1}));
    EXPECT_EQ(r.roi->mode, "pre");
    EXPECT_EQ(r.output.upsample, 2);
}

TEST(Recipe, IntegralFloatAcceptedForIntegers)
{
    const Recipe r = Recipe::fromJson(json::parse(R"({"output": {"upsample": 3.0}, "animation": {"frames": 12}})"));
    EXPECT_EQ(r.output.upsample, 3);
    EXPECT_EQ(r.animation.frames, 12);
}

// ---- unknown keys and wrong types -------------------------------------------------------

TEST(Recipe, UnknownKeyAtTopLevelSuggestsNearest)
{
    const std::string msg = inputError([] { Recipe::fromJson(json::parse(R"({"colour": null})")); });
    EXPECT_EQ(msg, R"(recipe: unknown key "colour"; did you mean "color"?)");
}

TEST(Recipe, UnknownNestedKeySuggestsNearest)
{
    EXPECT_EQ(parseError(R"({"lic": {"lenght": 20}})"), R"(recipe: unknown key "lic.lenght"; did you mean "length"?)");
    EXPECT_EQ(parseError(R"({"input": {"haloScale": 2}})"),
        R"(recipe: unknown key "input.haloScale"; did you mean "halo_scale"?)");
    EXPECT_EQ(parseError(R"({"input": {"surface": {"scalar": "speed", "treshold": 1}}})"),
        R"(recipe: unknown key "input.surface.treshold"; did you mean "threshold"?)");
}

TEST(Recipe, UnknownKeyWithoutCloseMatchListsValidKeys)
{
    const std::string msg = parseError(R"({"lic": {"zzzzzz": 1}})");
    EXPECT_CONTAINS(msg, R"(unknown key "lic.zzzzzz")");
    EXPECT_CONTAINS(msg, R"("engine")");
    EXPECT_CONTAINS(msg, R"("min_hits")");
}

TEST(Recipe, UnknownKeyUsesSourceName)
{
    const std::string msg = inputError([] { Recipe::fromJson(json::parse(R"({"lic": {"lenght": 1}})"), "my.json"); });
    EXPECT_CONTAINS(msg, "my.json: unknown key");
}

TEST(Recipe, WrongTypeNamesPathAndExpectedType)
{
    EXPECT_EQ(parseError(R"({"lic": {"length": "20"}})"), R"(recipe: lic.length: expected a number, got string "20")");
    EXPECT_CONTAINS(parseError(R"({"output": {"upsample": 2.5}})"), "output.upsample: expected an integer, got number 2.5");
    EXPECT_CONTAINS(parseError(R"({"output": {"write_input": 1}})"), "output.write_input: expected a boolean");
    EXPECT_CONTAINS(parseError(R"({"lic": {"engine": 3}})"), "lic.engine: expected a string, got number 3");
    EXPECT_CONTAINS(parseError(R"({"input": {"seed": -1}})"), "input.seed: expected a non-negative integer");
    EXPECT_CONTAINS(parseError(R"({"input": {"radii": 2}})"), "input.radii: expected an array of numbers");
    EXPECT_CONTAINS(parseError(R"({"input": {"radii": [1, "2"]}})"), "input.radii[1]: expected a number");
    EXPECT_CONTAINS(parseError(R"({"roi": {"scalar": "speed", "range": [1]}})"), "roi.range: expected [lo, hi]");
    EXPECT_CONTAINS(parseError(R"({"color": {"scalar": "speed", "range": "fixed"}})"),
        "color.range: expected \"auto\" or [lo, hi], got string \"fixed\"");
    EXPECT_CONTAINS(parseError(R"({"lic": 5})"), "lic: expected an object, got number 5");
    EXPECT_CONTAINS(parseError(R"({"roi": true})"), "roi: expected an object or null, got boolean true");
    EXPECT_CONTAINS(inputError([] { Recipe::fromJson(json::parse(R"({"threads": null})")); }),
        "threads: expected an integer, got null");
    EXPECT_CONTAINS(inputError([] { Recipe::fromJson(json::array()); }), "expected a JSON object at the top level");
}

// ---- malformed JSON and files -----------------------------------------------------------

TEST(Recipe, MalformedJsonStringGivesPosition)
{
    const std::string msg = inputError([] { vdbexport::parseRecipe("{\n  \"lic\": {\"length\": 20,}\n}", "inline"); });
    EXPECT_CONTAINS(msg, "inline: invalid JSON at line 2, column");
}

/// Recipe files in a scratch directory of each test's own.
using RecipeFile = lictest::TempDirTest;

TEST_F(RecipeFile, MalformedJsonFileGivesFileAndPosition)
{
    const auto path = mDir / "bad.json";
    {
        std::ofstream(path) << "{\"lic\": {\"length\": 20}\n\"threads\": 0}\n";
    }
    const std::string msg = inputError([&] { vdbexport::loadRecipeFile(path.string()); });
    EXPECT_CONTAINS(msg, path.string() + ": invalid JSON at line 2, column 9: syntax error");
}

TEST_F(RecipeFile, LoadRecipeFileParsesAndValidates)
{
    const auto good = mDir / "good.json";
    const auto bad = mDir / "range.json";
    {
        std::ofstream(good) << kDesignExample;
        std::ofstream(bad) << R"({"lic": {"step": 0}})";
    }
    const Recipe r = vdbexport::loadRecipeFile(good.string());
    EXPECT_EQ(r.animation.frames, 24);
    const std::string msg = inputError([&] { vdbexport::loadRecipeFile(bad.string()); });
    EXPECT_EQ(msg, bad.string() + ": lic.step: must be > 0 (got 0)");
}

TEST(Recipe, MissingRecipeFileNamesPath)
{
    const std::string msg = inputError([] { vdbexport::loadRecipeFile("/nonexistent/dir/recipe.json"); });
    EXPECT_CONTAINS(msg, "\"/nonexistent/dir/recipe.json\"");
    EXPECT_CONTAINS(msg, "not found");
}

TEST(Recipe, JsonCommentsAreAllowed)
{
    const Recipe r = vdbexport::parseRecipe("{ // longer lines\n \"lic\": {\"length\": 30} /* ok */ }");
    EXPECT_EQ(r.lic.length, 30);
}

// ---- validate ---------------------------------------------------------------------------

TEST(RecipeValidate, EachRuleNamesTheKey)
{
    struct Case
    {
        const char* patch;
        const char* expected;
    };
    const Case cases[] = {
        {R"({"output": {"upsample": 0}})", "output.upsample: must be in [1, 16] (got 0)"},
        {R"({"output": {"upsample": 17}})", "output.upsample: must be in [1, 16] (got 17)"},
        {R"({"output": {"contrast": "auto"}})", "output.contrast: must be one of \"stretch\", \"none\""},
        {R"({"lic": {"length": 0}})", "lic.length: must be in (0, 10000] (got 0)"},
        {R"({"lic": {"length": 10001}})", "lic.length: must be in (0, 10000] (got 10001)"},
        {R"({"lic": {"step": 0}})", "lic.step: must be > 0 (got 0)"},
        {R"({"lic": {"step": -0.5}})", "lic.step: must be > 0 (got -0.5)"},
        {R"({"lic": {"step": 30}})", "lic.step: must be <= lic.length = 20 (got 30)"},
        {R"({"lic": {"decay": 0}})", "lic.decay: must be in (0, 1) (got 0)"},
        {R"({"lic": {"decay": 1}})", "lic.decay: must be in (0, 1) (got 1)"},
        {R"({"lic": {"tolerance": 0}})", "lic.tolerance: must be > 0 (got 0)"},
        {R"({"lic": {"min_hits": 0}})", "lic.min_hits: must be in [1, 64] (got 0)"},
        {R"({"lic": {"min_hits": 65}})", "lic.min_hits: must be in [1, 64] (got 65)"},
        {R"({"lic": {"engine": "fats"}})",
            "lic.engine: must be one of \"auto\", \"naive\", \"fast\", \"splat\" (got \"fats\"); did you mean \"fast\"?"},
        {R"({"lic": {"kernel": "gauss"}})", "lic.kernel: must be one of \"box\", \"exp\" (got \"gauss\")"},
        {R"({"lic": {"integrator": "euler"}})", "lic.integrator: must be one of \"rk4\", \"rk45\""},
        {R"({"input": {"type": "dots"}})", "input.type: must be one of \"noise\", \"spots\""},
        {R"({"input": {"distribution": "grid"}})",
            "input.distribution: must be one of \"regular\", \"random\", \"jittered\", \"poisson\""},
        {R"({"input": {"spacing": 0}})", "input.spacing: must be > 0 (got 0)"},
        {R"({"input": {"jitter": -0.1}})", "input.jitter: must be in [0, 1] (got -0.1)"},
        {R"({"input": {"jitter": 1.5}})", "input.jitter: must be in [0, 1] (got 1.5)"},
        {R"({"input": {"radii": []}})", "input.radii: must be a non-empty array of radii"},
        {R"({"input": {"radii": [0, 1]}})", "input.radii[0]: must be > 0 (got 0)"},
        {R"({"input": {"halo_scale": 0.5}})", "input.halo_scale: must be >= 1 (got 0.5)"},
        {R"({"input": {"surface": {"threshold": 1}}})", "input.surface.scalar: must be a scalar name"},
        {R"({"input": {"surface": {"scalar": "speed"}, "seeds": "points.txt"}})",
            "input.seeds: must be \"\" with input.surface (spots come from the seeds file or the surface, not both) "
            "(got \"points.txt\")"},
        {R"({"roi": {"scalar": "speed", "range": [1, 0]}})", "roi.range: must be [lo, hi] with finite lo < hi (got [1, 0])"},
        {R"({"roi": {"scalar": "speed", "range": [1, 1]}})", "roi.range: must be [lo, hi] with finite lo < hi"},
        {R"({"roi": {"scalar": "speed", "mode": "during"}})", "roi.mode: must be one of \"pre\", \"post\""},
        {R"({"roi": {"range": [0, 1]}})", "roi.scalar: must be a scalar name"},
        {R"({"width": {"scalar": "speed", "range": [2, 1]}})", "width.range: must be [lo, hi] with finite lo < hi"},
        {R"({"color": {"scalar": "speed", "range": [5, -5]}})", "color.range: must be [lo, hi] with finite lo < hi"},
        {R"({"color": {"scalar": "speed", "colormap": ""}})", "color.colormap: must be a colormap name"},
        {R"({"animation": {"frames": 0}})", "animation.frames: must be in [1, 10000] (got 0)"},
        {R"({"animation": {"frames": 10001}})", "animation.frames: must be in [1, 10000] (got 10001)"},
        {R"({"threads": -1})", "threads: must be in [0, 1024] (got -1)"},
        {R"({"threads": 1025})", "threads: must be in [0, 1024] (got 1025)"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.patch);
        const std::string msg = validateError(c.patch);
        EXPECT_EQ(msg.rfind(c.expected, 0), 0u) << "message: \"" << msg << "\"\nexpected to start with: \""
                                                << c.expected << "\"";
    }
}

TEST(RecipeValidate, RadiiMustIncreaseStrictly)
{
    EXPECT_CONTAINS(validateError(R"({"input": {"radii": [1, 1]}})"), "input.radii[1]: must be > input.radii[0] = 1");
    EXPECT_CONTAINS(validateError(R"({"input": {"radii": [1, 2, 1.5]}})"),
        "input.radii[2]: must be > input.radii[1] = 2 (radii must be strictly increasing) (got 1.5)");
    const Recipe r = Recipe::fromJson(json::parse(R"({"input": {"radii": [0.5, 1, 2, 4]}})"));
    EXPECT_NO_THROW(r.validate());
}

TEST(RecipeValidate, NanIsRejected)
{
    Recipe r;
    r.lic.length = std::nan("");
    EXPECT_CONTAINS(inputError([&] { r.validate(); }), "lic.length: must be in (0, 10000] (got nan)");
    r = Recipe{};
    r.input.spacing = std::numeric_limits<double>::infinity();
    EXPECT_CONTAINS(inputError([&] { r.validate(); }), "input.spacing: must be > 0 (got inf)");
}

TEST(RecipeValidate, BoundaryValuesAreAccepted)
{
    const Recipe r = Recipe::fromJson(json::parse(R"({
        "output": {"upsample": 16}, "lic": {"length": 10000, "step": 10000, "min_hits": 64},
        "input": {"jitter": 1, "halo_scale": 1}, "animation": {"frames": 10000}, "threads": 1024})"));
    EXPECT_NO_THROW(r.validate());
}

TEST(RecipeValidate, PathsAreCheckedSeparately)
{
    Recipe r;
    EXPECT_NO_THROW(r.validate());
    EXPECT_CONTAINS(inputError([&] { r.validatePaths(); }), "--field");
    r.field.path = "in.vdb";
    EXPECT_CONTAINS(inputError([&] { r.validatePaths(); }), "--out");
    r.output.path = "out.vdb";
    EXPECT_NO_THROW(r.validatePaths());
}

// ---- ranges -----------------------------------------------------------------------------

TEST(Recipe, ColorRangeAutoOrArray)
{
    Recipe r = Recipe::fromJson(json::parse(R"({"color": {"scalar": "speed", "range": "auto"}})"));
    ASSERT_TRUE(r.color.has_value());
    EXPECT_FALSE(r.color->range.has_value());
    EXPECT_EQ(r.toJson()["color"]["range"], "auto");

    r = Recipe::fromJson(json::parse(R"({"color": {"scalar": "speed", "range": null}})"));
    EXPECT_FALSE(r.color->range.has_value());

    r = Recipe::fromJson(json::parse(R"({"color": {"scalar": "speed", "range": [0.5, 2]}})"));
    ASSERT_TRUE(r.color->range.has_value());
    EXPECT_EQ(*r.color->range, (std::array<double, 2>{0.5, 2.0}));
    EXPECT_EQ(r.toJson()["color"]["range"], json::parse("[0.5, 2.0]"));
}

TEST(Recipe, WidthRangeAbsentNullAutoOrArray)
{
    for (const char* text : {R"({"width": {"scalar": "speed"}})", R"({"width": {"scalar": "speed", "range": null}})",
             R"({"width": {"scalar": "speed", "range": "auto"}})"}) {
        const Recipe r = Recipe::fromJson(json::parse(text));
        ASSERT_TRUE(r.width.has_value()) << text;
        EXPECT_FALSE(r.width->range.has_value()) << text;
    }
    const Recipe r = Recipe::fromJson(json::parse(R"({"width": {"scalar": "speed", "range": [0, 3]}})"));
    EXPECT_EQ(r.width->range, (std::array<double, 2>{0, 3}));
}

TEST(Recipe, AllowedValues)
{
    EXPECT_EQ(vdbexport::allowedValues("lic.engine"), (std::vector<std::string>{"auto", "naive", "fast", "splat"}));
    EXPECT_EQ(vdbexport::allowedValues("input.distribution").size(), 4u);
    EXPECT_TRUE(vdbexport::allowedValues("lic.length").empty());
}

// ---- suggestKey -------------------------------------------------------------------------

TEST(SuggestKey, Basics)
{
    const std::vector<std::string> lic{"engine", "kernel", "length", "step", "decay", "integrator", "tolerance", "min_hits"};
    EXPECT_EQ(vdbexport::suggestKey("lenght", lic), "length"); // transposition
    EXPECT_EQ(vdbexport::suggestKey("lenth", lic), "length");  // deletion
    EXPECT_EQ(vdbexport::suggestKey("Length", lic), "length"); // case
    EXPECT_EQ(vdbexport::suggestKey("stp", lic), "step");
    EXPECT_EQ(vdbexport::suggestKey("minhits", lic), "min_hits");
    EXPECT_EQ(vdbexport::suggestKey("min-hits", lic), "min_hits");
    EXPECT_EQ(vdbexport::suggestKey("integ", lic), "integrator"); // prefix
    EXPECT_EQ(vdbexport::suggestKey("foo", lic), "");
    EXPECT_EQ(vdbexport::suggestKey("", lic), "");
    EXPECT_EQ(vdbexport::suggestKey("length", {}), "");
    EXPECT_EQ(vdbexport::suggestKey("colour", {"field", "output", "color", "roi"}), "color");
}

// ---- TerminalProgress -------------------------------------------------------------------

TEST(TerminalProgress, ForcedDrawsFinalLineWithStageAndPercent)
{
    FILE* f = std::tmpfile();
    ASSERT_NE(f, nullptr);
    {
        vdbexport::TerminalProgress progress(false, f, true);
        EXPECT_TRUE(progress.enabled());
        progress.begin("convolve", 1000);
        for (int i = 0; i < 10; ++i) progress.advance(100);
        progress.end();
    }
    const std::string out = readAll(f);
    std::fclose(f);
    EXPECT_CONTAINS(out, "convolve");
    EXPECT_CONTAINS(out, "100%");
    EXPECT_CONTAINS(out, "done in");
    EXPECT_CONTAINS(out, "\r");
    EXPECT_EQ(out.back(), '\n');
}

TEST(TerminalProgress, NotATerminalDrawsNothingButRecordsStages)
{
    FILE* f = std::tmpfile();
    ASSERT_NE(f, nullptr);
    vdbexport::TerminalProgress progress(false, f);
    EXPECT_FALSE(progress.enabled());
    progress.begin("trace", 10);
    progress.advance(10);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    progress.end();
    progress.begin("write", 0);
    progress.end();
    EXPECT_EQ(readAll(f), "");
    std::fclose(f);
    ASSERT_EQ(progress.stageSeconds().size(), 2u);
    EXPECT_EQ(progress.stageSeconds()[0].first, "trace");
    EXPECT_GE(progress.stageSeconds()[0].second, 0.015);
    EXPECT_EQ(progress.stageSeconds()[1].first, "write");
    EXPECT_GE(progress.stageSeconds()[1].second, 0.0);
}

TEST(TerminalProgress, QuietWinsOverForce)
{
    FILE* f = std::tmpfile();
    ASSERT_NE(f, nullptr);
    vdbexport::TerminalProgress progress(true, f, true);
    EXPECT_FALSE(progress.enabled());
    progress.begin("trace", 10);
    progress.end();
    EXPECT_EQ(readAll(f), "");
    std::fclose(f);
    EXPECT_EQ(progress.stageSeconds().size(), 1u);
}

TEST(TerminalProgress, ThreadSafeAdvanceAndUnknownTotal)
{
    FILE* f = std::tmpfile();
    ASSERT_NE(f, nullptr);
    vdbexport::TerminalProgress progress(false, f, true);
    progress.begin("splat", 0);
    std::vector<std::thread> workers;
    for (int t = 0; t < 4; ++t) {
        workers.emplace_back([&] {
            for (int i = 0; i < 100000; ++i) progress.advance(1);
        });
    }
    for (auto& w : workers) w.join();
    progress.begin("write", 4); // implicitly ends "splat"
    progress.advance(2);
    progress.finishLine();      // as before printing an error
    const std::string out = readAll(f);
    std::fclose(f);
    EXPECT_CONTAINS(out, "splat  400k");
    EXPECT_CONTAINS(out, "write [");
    EXPECT_EQ(out.back(), '\n');
    ASSERT_EQ(progress.stageSeconds().size(), 1u);
    EXPECT_EQ(progress.stageSeconds()[0].first, "splat");
}

TEST(TerminalProgress, CancelIsReported)
{
    vdbexport::TerminalProgress progress(true);
    EXPECT_FALSE(progress.wasInterrupted());
    progress.requestCancel();
    EXPECT_TRUE(progress.wasInterrupted());
}

// ---- field input keys (issue [inputs]) ------------------------------------------------------

TEST(RecipeField, DefaultsResolvedAndRoundTrip)
{
    const json j = Recipe{}.toJson()["field"];
    for (const char* key : {"path", "grid", "format", "voxel_size", "origin", "shape", "dtype", "resample", "crop", "mask",
                            "nan_policy"})
        EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_EQ(j["format"], "auto");
    EXPECT_TRUE(j["voxel_size"].is_null());
    EXPECT_TRUE(j["origin"].is_null());
    EXPECT_TRUE(j["crop"].is_null());
    EXPECT_EQ(j["dtype"], "float32");
    EXPECT_EQ(j["mask"], "none");
    EXPECT_EQ(j["nan_policy"], "refuse");

    const Recipe r = vdbexport::parseRecipe(R"({"field": {"path": "f.raw", "format": "raw", "voxel_size": 0.25,
        "origin": [1, -2, 3.5], "shape": [4, 5, 6], "dtype": ">f8", "resample": 0.5,
        "crop": [[0, 0, 0], [1, 2, 3]], "mask": "zero", "nan_policy": "zero"}})");
    EXPECT_EQ(r.field.format, "raw");
    ASSERT_TRUE(r.field.voxelSize && r.field.origin && r.field.shape && r.field.resample && r.field.crop);
    EXPECT_EQ(*r.field.voxelSize, 0.25);
    EXPECT_EQ((*r.field.origin)[1], -2.0);
    EXPECT_EQ((*r.field.shape)[2], 6.0);
    EXPECT_EQ((*r.field.crop)[1][2], 3.0);
    EXPECT_EQ(r.field.dtype, ">f8");
    EXPECT_EQ(Recipe::fromJson(r.toJson()), r);
    EXPECT_EQ(r.toJson()["field"]["crop"], json::parse("[[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]"));

    // Meshes (issue [cfd]): the formats, a series' time and PLOT3D's solution file.
    EXPECT_TRUE(j["time"].is_null());
    EXPECT_EQ(j["solution"], "");
    for (const char* format : {"vtu", "vts", "vtm", "vtpc", "pvd", "vtk-mesh", "plot3d", "openfoam"}) {
        const Recipe m = vdbexport::parseRecipe(json{{"field", {{"format", format}, {"time", 0.5}, {"solution", "a.q"}}}}.dump());
        EXPECT_EQ(m.field.format, format);
        ASSERT_TRUE(m.field.time);
        EXPECT_EQ(*m.field.time, 0.5);
        EXPECT_EQ(m.field.solution, "a.q");
        EXPECT_EQ(Recipe::fromJson(m.toJson()), m);
    }
}

TEST(RecipeField, ErrorsNameTheKey)
{
    EXPECT_NE(parseError(R"({"field": {"voxel_sise": 1}})").find("did you mean \"voxel_size\""), std::string::npos);
    EXPECT_NE(parseError(R"({"field": {"origin": [1, 2]}})").find("field.origin"), std::string::npos);
    EXPECT_NE(parseError(R"({"field": {"crop": [1, 2, 3]}})").find("field.crop"), std::string::npos);
    auto invalid = [](const std::string& patch) {
        return inputError([&] { vdbexport::parseRecipe(patch); });
    };
    EXPECT_NE(invalid(R"({"field": {"voxel_size": 0}})").find("field.voxel_size: must be > 0 (got 0)"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"voxel_size": -2}})").find("field.voxel_size"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"resample": 0}})").find("field.resample"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"shape": [4, 0, 4]}})").find("field.shape[1]"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"shape": [4, 2.5, 4]}})").find("field.shape[1]"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"crop": [[0, 0, 5], [1, 1, 1]]}})").find("on axis z"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"nan_policy": "zeros"}})").find("did you mean \"zero\""), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"format": "stl"}})").find("field.format"), std::string::npos);
    EXPECT_NE(parseError(R"({"field": {"time": "latest"}})").find("field.time"), std::string::npos);
    EXPECT_NE(invalid(R"({"field": {"dtype": "float16"}})").find("field.dtype"), std::string::npos);
}

// Found by fuzz_recipe: a number too large for a double is an out_of_range error in
// nlohmann::json, not a parse_error; it must still be a bad-input error.
TEST(RecipeField, HugeNumberIsInvalidJson)
{
    const std::string msg = inputError([] { vdbexport::parseRecipe("{\"lic\": {\"length\": 1e999999}}", "big.json"); });
    EXPECT_NE(msg.find("big.json: invalid JSON"), std::string::npos) << msg;
}

// The shipped example recipes (scripts/demo bakes one; docs point at both) must stay valid as
// the schema grows, and must say what their comments promise.
TEST(RecipeExamples, ShippedRecipesParse)
{
    const std::filesystem::path dir = std::filesystem::path(LICVDB_SOURCE_DIR) / "examples" / "recipes";
    int parsed = 0;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
        if (entry.path().extension() != ".json") continue;
        SCOPED_TRACE(entry.path().string());
        const Recipe r = vdbexport::loadRecipeFile(entry.path().string());
        EXPECT_FALSE(r.field.path.empty());
        EXPECT_FALSE(r.output.path.empty());
        ++parsed;
    }
    EXPECT_GE(parsed, 2);
    const Recipe halos = vdbexport::loadRecipeFile((dir / "tabbed-jet-halos.json").string());
    EXPECT_EQ(halos.input.type, "spots");
    EXPECT_TRUE(halos.roi.has_value());
    EXPECT_TRUE(halos.width.has_value());
    EXPECT_TRUE(halos.output.half);
}

// End-to-end tests of the `licvdb` command line: each test runs the built binary (LICVDB_EXE)
// in a fresh temporary directory, captures stdout, stderr and the exit status, and inspects the
// files it wrote with OpenVDB and vdbexport::describeVdb. Inputs are tiny (12³–16³ fields,
// short kernels) so the suite runs in seconds.
#include <gtest/gtest.h>

#include "CliRun.h"
#include "../unit/TempDirSuite.h"
#include "vdbexport/io/Info.h"
#include "vdbexport/io/AtomicWrite.h"
#include "vdbexport/io/FieldGrids.h"

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// ---- running the binary ---------------------------------------------------------------------

using cli_test::lower;
using cli_test::readText;
using cli_test::RunResult;

void writeText(const fs::path& p, const std::string& text)
{
    std::ofstream out(p, std::ios::binary);
    out << text;
    ASSERT_TRUE(out.good()) << "cannot write " << p;
}

/// Every active voxel value of a float grid must be finite and in [0, 1].
void expectUnitRange(const openvdb::FloatGrid& grid)
{
    std::size_t bad = 0;
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        const float v = *it;
        if (!(v >= 0.0f && v <= 1.0f)) ++bad;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    EXPECT_EQ(bad, 0u) << "grid " << grid.getName() << ": values outside [0,1]; range [" << lo << ", " << hi << "]";
}

/// World box of a grid's active voxels: index bbox min − ½ … max + ½ through the transform
/// (computed here independently of describeVdb and the bake).
openvdb::BBoxd worldBBox(const openvdb::GridBase& grid)
{
    const openvdb::CoordBBox ib = grid.evalActiveVoxelBoundingBox();
    openvdb::BBoxd out;
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d corner((c & 1) ? ib.max()[0] + 0.5 : ib.min()[0] - 0.5,
                                    (c & 2) ? ib.max()[1] + 0.5 : ib.min()[1] - 0.5,
                                    (c & 4) ? ib.max()[2] + 0.5 : ib.min()[2] - 0.5);
        out.expand(grid.transform().indexToWorld(corner));
    }
    return out;
}

void expectBBoxNear(const openvdb::BBoxd& a, const openvdb::BBoxd& b, double tol, const std::string& what)
{
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(a.min()[i], b.min()[i], tol) << what << ": min[" << i << "]";
        EXPECT_NEAR(a.max()[i], b.max()[i], tol) << what << ": max[" << i << "]";
    }
}

openvdb::BBoxd bboxFromJson(const json& j)
{
    return openvdb::BBoxd(openvdb::Vec3d(j.at(0).at(0).get<double>(), j.at(0).at(1).get<double>(),
                                         j.at(0).at(2).get<double>()),
                          openvdb::Vec3d(j.at(1).at(0).get<double>(), j.at(1).at(1).get<double>(),
                                         j.at(1).at(2).get<double>()));
}

/// All grids of a .vdb file by name (read with plain OpenVDB, not vdbexport).
std::map<std::string, openvdb::GridBase::Ptr> readAll(const fs::path& p)
{
    std::map<std::string, openvdb::GridBase::Ptr> out;
    openvdb::io::File file(p.string());
    file.open(/*delayLoad=*/false);
    for (auto it = file.beginName(); it != file.endName(); ++it) out[it.gridName()] = file.readGrid(it.gridName());
    file.close();
    return out;
}

openvdb::FloatGrid::Ptr readFloat(const fs::path& p, const std::string& name)
{
    auto grids = readAll(p);
    auto it = grids.find(name);
    if (it == grids.end()) return nullptr;
    return openvdb::GridBase::grid<openvdb::FloatGrid>(it->second);
}

/// Each test gets its own directory: `work` for inputs and outputs, `logs` for captured streams
/// (kept apart so "no output file was created" checks only see what licvdb wrote).
class CliTest : public lictest::TempDirTest
{
protected:
    CliTest() : TempDirTest({"work", "logs"}) {}

    fs::path work(const std::string& name = "") const { return name.empty() ? mDir / "work" : mDir / "work" / name; }

    /// Run licvdb with `args` in the work directory; stdin is /dev/null, stdout and stderr are captured.
    RunResult run(const std::vector<std::string>& args) { return cli_test::runLicvdb(work(), mDir / "logs", args); }

    /// `licvdb field PRESET --res RES --out NAME` into the work directory; returns the path.
    fs::path makeField(const std::string& name, const std::string& preset = "abc", const std::string& res = "12,12,12")
    {
        const fs::path p = work(name);
        const RunResult r = run({"field", preset, "--res", res, "--out", p.string(), "--quiet"});
        EXPECT_EQ(r.code, 0) << r.describe();
        EXPECT_TRUE(fs::is_regular_file(p)) << r.describe();
        return p;
    }

    /// A small, fast bake of `field` into `out`; `extra` flags are appended.
    RunResult bake(const fs::path& field, const fs::path& out, const std::vector<std::string>& extra = {})
    {
        std::vector<std::string> args{"bake", "--field", field.string(), "--out", out.string(),
                                      "--length", "4", "--step", "0.5", "--upsample", "2"};
        args.insert(args.end(), extra.begin(), extra.end());
        return run(args);
    }

    /// Names of the regular files in the work directory (recursively, relative).
    std::set<std::string> workFiles() const
    {
        std::set<std::string> out;
        for (const auto& e : fs::recursive_directory_iterator(work()))
            if (!e.is_directory()) out.insert(fs::relative(e.path(), work()).string());
        return out;
    }
};

// ---- 1. field → bake → info ------------------------------------------------------------------

TEST_F(CliTest, FieldBakeHappyPath)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("abc_lic.vdb");
    const RunResult r = bake(field, out);
    ASSERT_EQ(r.code, 0) << r.describe();
    ASSERT_TRUE(fs::is_regular_file(out)) << r.describe();

    // The field as written (dense 12³).
    auto fieldGrid = vdbexport::readVelocityGrid(field.string());
    ASSERT_TRUE(fieldGrid);
    EXPECT_EQ(fieldGrid->activeVoxelCount(), openvdb::Index64(12 * 12 * 12));

    auto grids = readAll(out);
    ASSERT_TRUE(grids.count("density")) << "grids in output: " << grids.size();
    auto density = openvdb::GridBase::grid<openvdb::FloatGrid>(grids["density"]);
    ASSERT_TRUE(density) << "density is a " << grids["density"]->valueType() << " grid, expected float";
    EXPECT_EQ(density->getGridClass(), openvdb::GRID_FOG_VOLUME);
    expectUnitRange(*density);

    // Dense preset: every output voxel active, as leaf voxels (no tiles).
    const openvdb::Index64 n = 12 * 2;
    EXPECT_EQ(density->activeVoxelCount(), n * n * n);
    EXPECT_EQ(density->tree().activeTileCount(), openvdb::Index64(0));

    // Values are not constant (an actual convolution happened).
    float lo = 1, hi = 0;
    for (auto it = density->cbeginValueOn(); it; ++it) {
        lo = std::min(lo, *it);
        hi = std::max(hi, *it);
    }
    EXPECT_GT(hi - lo, 0.1f);

    // Transform: field voxel size / upsample; same world box as the field (half-voxel alignment).
    const openvdb::Vec3d fvs = fieldGrid->voxelSize(), ovs = density->voxelSize();
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(ovs[i], fvs[i] / 2.0, 1e-9 * fvs[i]) << "axis " << i;
    const openvdb::BBoxd fieldBox = worldBBox(*fieldGrid), outBox = worldBBox(*density);
    expectBBoxNear(outBox, fieldBox, 1e-6, "output world bbox vs field world bbox");

    // Metadata on density.
    EXPECT_EQ(density->metaValue<std::string>("licvdb_version"), std::string(LICVDB_VERSION));
    const json recipe = json::parse(density->metaValue<std::string>("licvdb_recipe"));
    ASSERT_TRUE(recipe.is_object());
    EXPECT_DOUBLE_EQ(recipe.at("lic").at("length").get<double>(), 4.0);
    EXPECT_DOUBLE_EQ(recipe.at("lic").at("step").get<double>(), 0.5);
    EXPECT_EQ(recipe.at("output").at("upsample").get<int>(), 2);
    EXPECT_EQ(density->metaValue<std::string>("lic_engine"), "fast");
    EXPECT_EQ(density->metaValue<std::string>("lic_kernel"), "box");
    EXPECT_FLOAT_EQ(density->metaValue<float>("lic_length"), 4.0f);
    EXPECT_FLOAT_EQ(density->metaValue<float>("lic_step"), 0.5f);
    EXPECT_EQ(density->metaValue<openvdb::Int32>("lic_frames"), 1);
    EXPECT_EQ(density->metaValue<openvdb::Int32>("lic_frame"), 1);
    EXPECT_EQ(density->metaValue<bool>("lic_cyclic"), false);

    // describeVdb (the `licvdb info` model) agrees.
    const json d = vdbexport::describeVdb(out.string());
    const json* dd = nullptr;
    for (const auto& g : d.at("grids"))
        if (g.at("name") == "density") dd = &g;
    ASSERT_NE(dd, nullptr) << d.dump(2);
    EXPECT_EQ(dd->at("class"), "fog volume");
    EXPECT_EQ(dd->at("value_type"), "float");
    EXPECT_EQ(dd->at("active_tiles").get<std::uint64_t>(), 0u);
    expectBBoxNear(bboxFromJson(dd->at("world_bbox")), fieldBox, 1e-6, "describeVdb world_bbox");

    // Sidecar manifest.
    const fs::path manifestPath = work("abc_lic.licvdb.json");
    ASSERT_TRUE(fs::is_regular_file(manifestPath)) << "no sidecar manifest " << manifestPath;
    const json manifest = json::parse(readText(manifestPath));
    ASSERT_TRUE(manifest.contains("grids")) << manifest.dump(2);
    const json* mg = nullptr;
    for (const auto& g : manifest.at("grids"))
        if (g.value("name", "") == "density") mg = &g;
    ASSERT_NE(mg, nullptr) << manifest.dump(2);
    ASSERT_TRUE(mg->contains("world_bbox")) << mg->dump();
    expectBBoxNear(bboxFromJson(mg->at("world_bbox")), fieldBox, 1e-6, "manifest world_bbox");
    EXPECT_DOUBLE_EQ(manifest.at("recipe").at("lic").at("length").get<double>(), 4.0);

    // No temporary files left behind.
    for (const auto& f : workFiles()) EXPECT_EQ(f.find(".tmp-"), std::string::npos) << "left over: " << f;
    EXPECT_EQ(workFiles(), (std::set<std::string>{"abc.vdb", "abc_lic.vdb", "abc_lic.licvdb.json"}));
}

// ---- 2. --json and --quiet -------------------------------------------------------------------

TEST_F(CliTest, JsonSummaryAndQuiet)
{
    const fs::path field = makeField("abc.vdb");

    const RunResult j = bake(field, work("a.vdb"), {"--json"});
    ASSERT_EQ(j.code, 0) << j.describe();
    json s;
    ASSERT_NO_THROW(s = json::parse(j.out)) << "stdout is not JSON:\n" << j.describe();
    ASSERT_TRUE(s.is_object()) << j.out;
    ASSERT_TRUE(s.contains("output_voxels")) << j.out;
    EXPECT_EQ(s.at("output_voxels").get<std::uint64_t>(), 24u * 24u * 24u);
    ASSERT_TRUE(s.contains("streamlines")) << j.out;
    EXPECT_GT(s.at("streamlines").get<double>(), 0);
    ASSERT_TRUE(s.contains("samples_per_voxel")) << j.out;
    EXPECT_GT(s.at("samples_per_voxel").get<double>(), 0);
    ASSERT_TRUE(s.contains("seconds") && s.at("seconds").contains("total")) << j.out;
    EXPECT_TRUE(s.at("seconds").at("total").is_number()) << j.out;
    EXPECT_GE(s.at("seconds").at("total").get<double>(), 0.0);

    // Without --quiet a message goes to stderr (so the --quiet check below means something).
    const RunResult loud = bake(field, work("b.vdb"));
    ASSERT_EQ(loud.code, 0) << loud.describe();
    EXPECT_FALSE(loud.err.empty()) << loud.describe();

    const RunResult q = bake(field, work("c.vdb"), {"--quiet"});
    ASSERT_EQ(q.code, 0) << q.describe();
    EXPECT_EQ(q.err, "") << q.describe();
    EXPECT_TRUE(fs::is_regular_file(work("c.vdb")));

    // --quiet also on `field`.
    const RunResult qf = run({"field", "abc", "--res", "8", "--out", work("f.vdb").string(), "--quiet"});
    ASSERT_EQ(qf.code, 0) << qf.describe();
    EXPECT_EQ(qf.err, "") << qf.describe();
}

// ---- 3. --write-input ------------------------------------------------------------------------

TEST_F(CliTest, WriteInputAddsInputGrid)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("lic.vdb");
    const RunResult r = bake(field, out, {"--write-input", "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();

    auto input = readFloat(out, "input");
    ASSERT_TRUE(input) << "no float grid `input` in " << out;
    auto density = readFloat(out, "density");
    ASSERT_TRUE(density);
    EXPECT_EQ(input->activeVoxelCount(), density->activeVoxelCount());
    EXPECT_TRUE(input->tree().hasSameTopology(density->tree()));
    expectUnitRange(*input);
    float lo = 1, hi = 0;
    for (auto it = input->cbeginValueOn(); it; ++it) {
        lo = std::min(lo, *it);
        hi = std::max(hi, *it);
    }
    EXPECT_GT(hi - lo, 0.1f) << "input texture looks constant";

    // Without the flag there is no `input` grid.
    const fs::path out2 = work("lic2.vdb");
    ASSERT_EQ(bake(field, out2, {"--quiet"}).code, 0);
    EXPECT_FALSE(readFloat(out2, "input"));
}

// ---- 4. recipe and flag precedence -----------------------------------------------------------

TEST_F(CliTest, WriteTangentAddsUnitFlowDirection)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("lic.vdb");
    const RunResult r = bake(field, out, {"--write-tangent", "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    auto grids = readAll(out);
    ASSERT_TRUE(grids.count("tangent")) << "no `tangent` grid in " << out;
    auto tangent = openvdb::gridPtrCast<openvdb::Vec3SGrid>(grids["tangent"]);
    ASSERT_TRUE(tangent) << "`tangent` is not a vec3s grid";
    auto density = readFloat(out, "density");
    EXPECT_TRUE(tangent->tree().hasSameTopology(density->tree()));
    // ABC flow at a voxel centre: the tangent is its normalised velocity.
    const double A = std::sqrt(3.0), B = std::sqrt(2.0), C = 1.0;
    int checked = 0;
    for (auto it = tangent->cbeginValueOn(); it && checked < 200; ++it, ++checked) {
        const openvdb::Vec3d p = tangent->indexToWorld(it.getCoord());
        openvdb::Vec3d v(A * std::sin(p[2]) + C * std::cos(p[1]), B * std::sin(p[0]) + A * std::cos(p[2]),
                         C * std::sin(p[1]) + B * std::cos(p[0]));
        const openvdb::Vec3d t = *it;
        EXPECT_NEAR(t.length(), 1.0, 1e-5);
        EXPECT_GT(t.dot(v.unitSafe()), 0.95) << "at " << p; // trilinear field vs closed form
    }
    EXPECT_EQ(checked, 200);
}

TEST_F(CliTest, ColourByFileScalarWritesColorScalarAndRamp)
{
    // tabbed-jet's `temperature` is hottest on the jet axis: `scalar` must be higher there.
    const fs::path field = makeField("jet.vdb", "tabbed-jet", "20,20,30");
    const fs::path recipe = work("c.json");
    writeText(recipe, R"({"color": {"scalar": "temperature", "colormap": "red-yellow", "range": [300, 360]}})");
    const fs::path out = work("lic.vdb");
    const RunResult r = bake(field, out, {"--recipe", recipe.string(), "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    auto grids = readAll(out);
    ASSERT_TRUE(grids.count("color") && grids.count("scalar")) << r.describe();
    auto color = openvdb::gridPtrCast<openvdb::Vec3SGrid>(grids["color"]);
    auto scalar = openvdb::gridPtrCast<openvdb::FloatGrid>(grids["scalar"]);
    auto density = readFloat(out, "density");
    ASSERT_TRUE(color && scalar && density);
    EXPECT_TRUE(color->tree().hasSameTopology(density->tree()));
    EXPECT_TRUE(scalar->tree().hasSameTopology(density->tree()));
    expectUnitRange(*scalar);
    const auto bb = density->evalActiveVoxelBoundingBox();
    const openvdb::Coord mid((bb.min()[0] + bb.max()[0]) / 2, (bb.min()[1] + bb.max()[1]) / 2, bb.min()[2] + 2);
    const openvdb::Coord edge(bb.min()[0], bb.min()[1], bb.min()[2] + 2);
    EXPECT_GT(scalar->tree().getValue(mid), scalar->tree().getValue(edge) + 0.5f);
    // red-yellow in scene-linear: the hot axis is yellower (more green) than the cool edge.
    EXPECT_GT(color->tree().getValue(mid)[1], color->tree().getValue(edge)[1]);
    // Metadata and manifest carry the ramp for renderers.
    EXPECT_EQ(density->metaValue<std::string>("lic_colormap"), "red-yellow");
    EXPECT_EQ(density->metaValue<std::string>("lic_color_scalar"), "temperature");
    const json m = json::parse(readText(work("lic.licvdb.json")));
    EXPECT_EQ(m["colormap"]["name"], "red-yellow");
    EXPECT_EQ(m["colormap"]["range"][0], 300.0);
    EXPECT_EQ(m["colormap"]["range"][1], 360.0);
    EXPECT_GE(m["colormap"]["points"].size(), 2u);
}

TEST_F(CliTest, ColourByDerivedVorticityWithCsvLut)
{
    const fs::path field = makeField("rot.vdb", "rotation", "12,12,12");
    const fs::path lut = work("lut.csv");
    writeText(lut, "# value,r,g,b\n0,0,0,0\n1,255,255,255\n");
    const fs::path recipe = work("v.json");
    writeText(recipe, json{{"color", {{"scalar", "vorticity"}, {"colormap", lut.string()}}}}.dump());
    const fs::path out = work("lic.vdb");
    const RunResult r = bake(field, out, {"--recipe", recipe.string(), "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    auto density = readFloat(out, "density");
    ASSERT_TRUE(density);
    // Solid-body rotation: vorticity 2 everywhere, so the automatic range is degenerate and the
    // bake must still succeed with a constant scalar.
    const auto range = density->metaValue<openvdb::Vec2d>("lic_color_range");
    EXPECT_NEAR(range[0], 2.0, 1e-3);

    // Unknown scalar and colormap: exit 2, named.
    writeText(recipe, R"({"color": {"scalar": "enstrophy"}})");
    const RunResult bad = bake(field, work("bad.vdb"), {"--recipe", recipe.string()});
    EXPECT_EQ(bad.code, 2) << bad.describe();
    EXPECT_NE(bad.err.find("enstrophy"), std::string::npos) << bad.describe();
    EXPECT_FALSE(fs::exists(work("bad.vdb")));
    writeText(recipe, R"({"color": {"scalar": "speed", "colormap": "jet"}})");
    const RunResult bad2 = bake(field, work("bad2.vdb"), {"--recipe", recipe.string()});
    EXPECT_EQ(bad2.code, 2) << bad2.describe();
    EXPECT_NE(bad2.err.find("viridis"), std::string::npos) << bad2.describe();
}

TEST_F(CliTest, OrientedExpKernel)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("exp.vdb");
    const RunResult r = bake(field, out, {"--kernel", "exp", "--decay", "0.8", "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    auto density = readFloat(out, "density");
    ASSERT_TRUE(density);
    expectUnitRange(*density);
    EXPECT_EQ(density->metaValue<std::string>("lic_kernel"), "exp");
    EXPECT_FLOAT_EQ(density->metaValue<float>("lic_decay"), 0.8f);
    const RunResult bad = bake(field, work("bad.vdb"), {"--kernel", "exp", "--decay", "1"});
    EXPECT_EQ(bad.code, 2) << bad.describe();
    EXPECT_NE(bad.err.find("decay"), std::string::npos) << bad.describe();
    EXPECT_FALSE(fs::exists(work("bad.vdb")));
}

TEST_F(CliTest, SpotFlagsMapOntoTheRecipeAndWriteHaloAndSeries)
{
    const fs::path field = makeField("jet.vdb", "tabbed-jet", "16,16,24");
    const fs::path out = work("spots.vdb");
    const RunResult r = bake(field, out,
                             {"--input", "spots", "--distribution", "jittered", "--jitter", "0.5", "--spacing", "5",
                              "--radii", "0.75,1.5", "--halo-scale", "2.5", "--width", "speed", "--width-invert",
                              "--write-series", "--roi", "speed", "--roi-range", "0.1,5", "--roi-mode", "post",
                              "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const auto grids = readAll(out);
    for (const char* name : {"density", "halo", "density_w1", "density_w2", "halo_w1", "halo_w2"})
        EXPECT_TRUE(grids.count(name)) << name;
    auto density = readFloat(out, "density");
    ASSERT_TRUE(density);
    expectUnitRange(*density);
    EXPECT_EQ(density->metaValue<std::string>("lic_input"), "spots");
    EXPECT_GT(density->metaValue<openvdb::Int64>("lic_spot_count"), 0);
    const json recipe = json::parse(density->metaValue<std::string>("licvdb_recipe"));
    EXPECT_EQ(recipe["input"]["distribution"], "jittered");
    EXPECT_EQ(recipe["input"]["radii"], json::array({0.75, 1.5}));
    EXPECT_EQ(recipe["input"]["halo_scale"], 2.5);
    EXPECT_EQ(recipe["width"]["scalar"], "speed");
    EXPECT_EQ(recipe["width"]["invert"], true);
    EXPECT_EQ(recipe["roi"]["mode"], "post");
    EXPECT_EQ(recipe["roi"]["range"], json::array({0.1, 5.0}));
    EXPECT_EQ(recipe["output"]["write_series"], true);
    const json manifest = json::parse(readText(work("spots.licvdb.json")));
    EXPECT_EQ(manifest["input"], "spots");
    EXPECT_EQ(manifest["spots"]["count"].get<openvdb::Int64>(), density->metaValue<openvdb::Int64>("lic_spot_count"));

    // Flags that make no sense alone are refused, naming the flag; nothing is written.
    const std::vector<std::vector<std::string>> bad{
        {"--input", "spots", "--roi", "speed"},                  // no range
        {"--input", "spots", "--radii", "1,x"},                  // not a number
        {"--input", "spots", "--radii", "2,1"},                  // not increasing
        {"--input", "spots", "--distribution", "hexagonal"},     // unknown distribution
        {"--input", "spots", "--width-invert"},                  // no width scalar
        {"--width", "speed"},                                    // width needs spots
        {"--input", "spots", "--radii", "1,2"},                  // unused levels
        {"--input", "spots", "--roi", "nonesuch", "--roi-range", "0,1"}, // unknown scalar
    };
    for (const auto& extra : bad) {
        auto args = extra;
        args.push_back("--quiet");
        const RunResult b = bake(field, work("bad.vdb"), args);
        EXPECT_EQ(b.code, 2) << b.describe();
        EXPECT_FALSE(b.err.empty());
        EXPECT_FALSE(fs::exists(work("bad.vdb"))) << b.describe();
    }
}

TEST_F(CliTest, HalfStorageHalvesTheFileAndReadsBackAsFloat)
{
    // The same spot bake written as 32-bit and as 16-bit floats: the half file is much smaller,
    // has the same grids and topology, reads back as float/vec3s grids (plain OpenVDB, and
    // `licvdb info` and `render`), and agrees with the full-precision values to half precision.
    const fs::path field = makeField("jet.vdb", "tabbed-jet", "16,16,24");
    const std::vector<std::string> args{"--input", "spots", "--spacing", "5", "--write-tangent", "--color",
                                        "temperature", "--quiet"};
    const fs::path full = work("full.vdb"), half = work("half.vdb");
    ASSERT_EQ(bake(field, full, args).code, 0);
    auto halfArgs = args;
    halfArgs.push_back("--half");
    const RunResult r = bake(field, half, halfArgs);
    ASSERT_EQ(r.code, 0) << r.describe();
    const auto fullSize = fs::file_size(full), halfSize = fs::file_size(half);
    EXPECT_LT(double(halfSize), 0.7 * double(fullSize)) << fullSize << " vs " << halfSize << " bytes";

    const auto a = readAll(full), b = readAll(half);
    ASSERT_EQ(a.size(), b.size());
    for (const char* name : {"density", "halo", "scalar"}) {
        auto fa = openvdb::gridPtrCast<openvdb::FloatGrid>(a.at(name));
        auto fb = openvdb::gridPtrCast<openvdb::FloatGrid>(b.at(name));
        ASSERT_TRUE(fa && fb) << name;
        EXPECT_TRUE(fa->tree().hasSameTopology(fb->tree())) << name;
        double worst = 0;
        for (auto it = fa->cbeginValueOn(); it; ++it)
            worst = std::max(worst, std::abs(double(*it) - double(fb->tree().getValue(it.getCoord()))));
        EXPECT_LE(worst, 1e-3) << name; // values in [0, 1]: half spacing is <= 2^-11
        EXPECT_GT(fa->activeVoxelCount(), 0u);
    }
    for (const char* name : {"tangent", "color"}) {
        auto va = openvdb::gridPtrCast<openvdb::Vec3SGrid>(a.at(name));
        auto vb = openvdb::gridPtrCast<openvdb::Vec3SGrid>(b.at(name));
        ASSERT_TRUE(va && vb) << name;
        double worst = 0;
        for (auto it = va->cbeginValueOn(); it; ++it)
            worst = std::max(worst, double((*it - vb->tree().getValue(it.getCoord())).length()));
        EXPECT_LE(worst, 2e-3) << name;
    }
    const json recipe = json::parse(readText(work("half.licvdb.json")))["recipe"];
    EXPECT_EQ(recipe["output"]["half"], true);
    const RunResult info = run({"info", half.string()});
    EXPECT_EQ(info.code, 0) << info.describe();
    EXPECT_NE(info.out.find("density"), std::string::npos) << info.describe();
    const RunResult render = run({"render", half.string(), "--out", work("half.png").string(), "--size", "32,32",
                                  "--quiet"});
    EXPECT_EQ(render.code, 0) << render.describe();
    EXPECT_TRUE(fs::exists(work("half.png")));
}

TEST_F(CliTest, CyclicSequence)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("loop.vdb");
    const RunResult r = bake(field, out, {"--frames", "4", "--json", "--quiet"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json summary = json::parse(r.out);
    EXPECT_EQ(summary["frames"], 4);
    std::vector<openvdb::FloatGrid::Ptr> frames;
    for (int f = 1; f <= 4; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "loop_%04d.vdb", f);
        auto d = readFloat(work(name), "density");
        ASSERT_TRUE(d) << "missing frame " << name;
        EXPECT_EQ(d->metaValue<openvdb::Int32>("lic_frames"), 4);
        EXPECT_EQ(d->metaValue<openvdb::Int32>("lic_frame"), f);
        EXPECT_TRUE(d->metaValue<bool>("lic_cyclic"));
        expectUnitRange(*d);
        frames.push_back(d);
    }
    EXPECT_FALSE(fs::exists(out)) << "a loop writes numbered files only";
    const json m = json::parse(readText(work("loop.licvdb.json")));
    EXPECT_EQ(m["frames"], 4);
    EXPECT_EQ(m["cyclic"], true);
    ASSERT_EQ(m["files"].size(), 4u);
    EXPECT_EQ(m["files"][0], "loop_0001.vdb");
    EXPECT_EQ(m["files"][3], "loop_0004.vdb");
    // Consecutive frames differ (the texture moves).
    double diff = 0;
    auto acc = frames[1]->getConstAccessor();
    for (auto it = frames[0]->cbeginValueOn(); it; ++it) diff += std::abs(*it - acc.getValue(it.getCoord()));
    EXPECT_GT(diff / double(frames[0]->activeVoxelCount()), 0.01);
}

TEST_F(CliTest, RecipeSetsLengthAndFlagOverrides)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path recipe = work("r.json");
    const fs::path outR = work("from_recipe.vdb");
    writeText(recipe, json{{"field", {{"path", field.string()}}},
                           {"output", {{"path", outR.string()}, {"upsample", 1}}},
                           {"lic", {{"length", 3}, {"step", 0.5}}}}
                          .dump(2));

    // Paths and length from the recipe alone.
    const RunResult a = run({"bake", "--recipe", recipe.string(), "--quiet"});
    ASSERT_EQ(a.code, 0) << a.describe();
    auto dA = readFloat(outR, "density");
    ASSERT_TRUE(dA);
    EXPECT_FLOAT_EQ(dA->metaValue<float>("lic_length"), 3.0f);
    EXPECT_EQ(dA->activeVoxelCount(), openvdb::Index64(12 * 12 * 12)); // recipe's upsample 1

    // A flag overrides the recipe's length (and --out its path); the rest of the recipe stays.
    const fs::path outF = work("flag.vdb");
    const RunResult b = run({"bake", "--recipe", recipe.string(), "--length", "5", "--out", outF.string(), "--quiet"});
    ASSERT_EQ(b.code, 0) << b.describe();
    auto dB = readFloat(outF, "density");
    ASSERT_TRUE(dB);
    EXPECT_FLOAT_EQ(dB->metaValue<float>("lic_length"), 5.0f);
    const json rb = json::parse(dB->metaValue<std::string>("licvdb_recipe"));
    EXPECT_DOUBLE_EQ(rb.at("lic").at("length").get<double>(), 5.0);
    EXPECT_EQ(rb.at("output").at("upsample").get<int>(), 1);
    EXPECT_EQ(dB->activeVoxelCount(), openvdb::Index64(12 * 12 * 12));
}

// ---- 5. info, help, version ------------------------------------------------------------------

// `licvdb help --json`: the choices from their tables (the add-on's lists are checked against it
// in Blender), each one accepted by `bake` and named in `help bake`.
TEST_F(CliTest, HelpJsonListsTheChoicesBakeAccepts)
{
    const RunResult r = run({"help", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    json c;
    ASSERT_NO_THROW(c = json::parse(r.out)) << r.describe();
    EXPECT_EQ(c.at("kernels"), json({"box", "exp"}));
    EXPECT_EQ(c.at("engines"), json({"naive", "fast", "splat"}));
    EXPECT_EQ(c.at("distributions"), json({"regular", "random", "jittered", "poisson"}));
    EXPECT_EQ(c.at("scalars").size(), 6u);
    EXPECT_EQ(c.at("colormaps").size(), 8u);
    const RunResult help = run({"help", "bake"});
    for (const char* key : {"kernels", "engines", "scalars", "colormaps"})
        for (const auto& n : c.at(key)) EXPECT_NE(help.out.find(n.get<std::string>()), std::string::npos) << key << " " << n;
    const fs::path field = makeField("abc.vdb");
    for (const auto& m : c.at("colormaps")) {
        const RunResult b = bake(field, work("cm.vdb"), {"--color", "speed", "--colormap", m.get<std::string>(), "--quiet"});
        EXPECT_EQ(b.code, 0) << m << "\n" << b.describe();
    }
    for (const auto& k : c.at("kernels")) {
        const RunResult b = bake(field, work("k.vdb"), {"--kernel", k.get<std::string>(), "--quiet"});
        EXPECT_EQ(b.code, 0) << k << "\n" << b.describe();
    }
}

TEST_F(CliTest, InfoHelpVersion)
{
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("lic.vdb");
    ASSERT_EQ(bake(field, out, {"--write-input", "--quiet"}).code, 0);

    const RunResult info = run({"info", out.string(), "--json"});
    ASSERT_EQ(info.code, 0) << info.describe();
    json d;
    ASSERT_NO_THROW(d = json::parse(info.out)) << info.describe();
    ASSERT_TRUE(d.is_object() && d.contains("grids")) << info.out;
    std::set<std::string> names;
    for (const auto& g : d.at("grids")) names.insert(g.at("name").get<std::string>());
    EXPECT_EQ(names, (std::set<std::string>{"density", "input"}));

    // Text info mentions the grids too.
    const RunResult text = run({"info", out.string()});
    ASSERT_EQ(text.code, 0) << text.describe();
    EXPECT_NE(text.out.find("density"), std::string::npos) << text.describe();

    const RunResult hb = run({"help", "bake"});
    EXPECT_EQ(hb.code, 0) << hb.describe();
    EXPECT_NE(hb.out.find("--length"), std::string::npos) << hb.describe();

    const RunResult hn = run({"help", "nosuch"});
    EXPECT_EQ(hn.code, 2) << hn.describe();
    EXPECT_NE(hn.err.find("nosuch"), std::string::npos) << hn.describe();

    const std::string version = std::string("licvdb ") + LICVDB_VERSION;
    // No command at all: the synopsis (every command), exit 2; `help` alone: the same synopsis, exit 0
    // (not the help of the `help` command).
    const RunResult none = run({});
    EXPECT_EQ(none.code, 2) << none.describe();
    const RunResult help = run({"help"});
    EXPECT_EQ(help.code, 0) << help.describe();
    // The list's heading is CLI11's: "Subcommands:" in 2.1 (Debian 12), "SUBCOMMANDS:" in 2.6 (sid).
    const auto hasHeading = [](const std::string& s) {
        return s.find("Subcommands:") != std::string::npos || s.find("SUBCOMMANDS:") != std::string::npos;
    };
    EXPECT_TRUE(hasHeading(none.err)) << none.describe();
    EXPECT_TRUE(hasHeading(help.out)) << help.describe();
    for (const char* command : {"field", "convert", "bake", "info", "render"}) {
        EXPECT_NE(none.err.find(command), std::string::npos) << command << "\n" << none.describe();
        EXPECT_NE(help.out.find(command), std::string::npos) << command << "\n" << help.describe();
    }

    const RunResult v = run({"--version"});
    EXPECT_EQ(v.code, 0) << v.describe();
    EXPECT_NE(v.out.find(version), std::string::npos) << v.describe();

    const RunResult vs = run({"version"});
    EXPECT_EQ(vs.code, 0) << vs.describe();
    EXPECT_NE(vs.out.find(version), std::string::npos) << vs.describe();
    // The heap allocator, as the build chose it: jemalloc with transparent huge pages read back
    // from jemalloc itself (malloc_conf took effect), or the C library's malloc.
#ifdef LICVDB_JEMALLOC
    EXPECT_NE(vs.out.find("allocator: jemalloc 5"), std::string::npos) << vs.describe();
    EXPECT_NE(vs.out.find("transparent huge pages: always"), std::string::npos) << vs.describe();
#else
    EXPECT_NE(vs.out.find("allocator: the C library's malloc"), std::string::npos) << vs.describe();
#endif
}

// ---- 6. determinism across thread counts -----------------------------------------------------

/// Same active topology and bit-identical active values.
void expectBitIdentical(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b, const std::string& what)
{
    EXPECT_EQ(a.activeVoxelCount(), b.activeVoxelCount()) << what;
    EXPECT_TRUE(a.tree().hasSameTopology(b.tree())) << what;
    auto acc = b.getConstAccessor();
    std::size_t differ = 0, inactive = 0;
    std::string first;
    for (auto it = a.cbeginValueOn(); it; ++it) {
        float vb = 0;
        if (!acc.probeValue(it.getCoord(), vb)) {
            ++inactive;
            continue;
        }
        const float va = *it;
        if (std::memcmp(&va, &vb, sizeof(float)) != 0) {
            if (differ++ == 0) {
                std::ostringstream s;
                s.precision(9);
                s << it.getCoord() << ": " << va << " vs " << vb;
                first = s.str();
            }
        }
    }
    EXPECT_EQ(inactive, 0u) << what << ": voxels active in one and not the other";
    EXPECT_EQ(differ, 0u) << what << ": values differ, first at " << first;
}

TEST_F(CliTest, DeterministicAcrossThreadCounts)
{
    const fs::path field = makeField("abc.vdb", "abc", "16,16,16");
    for (const std::string engine : {"fast", "naive"}) {
        SCOPED_TRACE("engine " + engine);
        const fs::path o1 = work(engine + "_t1.vdb"), o2 = work(engine + "_t2.vdb");
        const RunResult r1 = bake(field, o1, {"--engine", engine, "--threads", "1", "--write-input", "--quiet"});
        ASSERT_EQ(r1.code, 0) << r1.describe();
        const RunResult r2 = bake(field, o2, {"--engine", engine, "--threads", "2", "--write-input", "--quiet"});
        ASSERT_EQ(r2.code, 0) << r2.describe();
        for (const std::string grid : {"density", "input"}) {
            auto a = readFloat(o1, grid), b = readFloat(o2, grid);
            ASSERT_TRUE(a && b) << grid;
            expectBitIdentical(*a, *b, engine + " " + grid + ": --threads 1 vs 2");
        }
    }
}

// ---- 7. bad input ----------------------------------------------------------------------------

struct BadCase
{
    std::string name;
    /// Creates inputs in the work directory (given) and returns the licvdb arguments.
    std::function<std::vector<std::string>(const fs::path& work, const fs::path& abcField)> setup;
    /// Words that stderr must contain (case-insensitive).
    std::vector<std::string> words;
};

/// A velocity field file derived from the abc field: `edit` changes the grid before writing.
fs::path editedField(const fs::path& abc, const fs::path& out, const std::function<void(openvdb::Vec3SGrid&)>& edit)
{
    auto g = vdbexport::readVelocityGrid(abc.string());
    edit(*g);
    vdbexport::writeVdbAtomic(out.string(), {g});
    return out;
}

/// A small bake; `extra` flags are appended, and replace the defaults --length 4, --step 0.5 and
/// --upsample 1 when they name the same flag (CLI11 rejects a flag given twice).
std::vector<std::string> bakeArgs(const fs::path& field, const fs::path& out, std::vector<std::string> extra = {})
{
    std::vector<std::string> a{"bake", "--field", field.string(), "--out", out.string(), "--quiet"};
    for (const auto& [flag, value] : std::vector<std::pair<std::string, std::string>>{
             {"--length", "4"}, {"--step", "0.5"}, {"--upsample", "1"}}) {
        if (std::find(extra.begin(), extra.end(), flag) == extra.end()) {
            a.push_back(flag);
            a.push_back(value);
        }
    }
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

const std::vector<BadCase>& badCases()
{
    static const std::vector<BadCase> cases = {
        {"missing field file",
         [](const fs::path& w, const fs::path&) { return bakeArgs(w / "nosuch.vdb", w / "out.vdb"); },
         {"nosuch.vdb", "not found"}},
        {"field path is a directory",
         [](const fs::path& w, const fs::path&) {
             fs::create_directories(w / "adir.vdb");
             return bakeArgs(w / "adir.vdb", w / "out.vdb");
         },
         {"directory"}},
        {"empty file",
         [](const fs::path& w, const fs::path&) {
             writeText(w / "empty.vdb", "");
             return bakeArgs(w / "empty.vdb", w / "out.vdb");
         },
         {"empty"}},
        {"text file",
         [](const fs::path& w, const fs::path&) {
             writeText(w / "notes.vdb", "this is not a volume\nat all\n");
             return bakeArgs(w / "notes.vdb", w / "out.vdb");
         },
         {"not an OpenVDB file"}},
        {"vdb with only a float grid",
         [](const fs::path& w, const fs::path&) {
             auto g = openvdb::FloatGrid::create(0.0f);
             g->setName("temperature");
             auto acc = g->getAccessor();
             for (int i = 0; i < 4; ++i)
                 for (int j = 0; j < 4; ++j)
                     for (int k = 0; k < 4; ++k) acc.setValue(openvdb::Coord(i, j, k), float(i + j + k));
             vdbexport::writeVdbAtomic((w / "scalar.vdb").string(), {g});
             return bakeArgs(w / "scalar.vdb", w / "out.vdb");
         },
         {"Vec3", "temperature", "float"}},
        {"--grid nosuch",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--grid", "nosuch"}); },
         {"nosuch", "velocity"}},
        {"field of all zeros",
         [](const fs::path& w, const fs::path& abc) {
             const fs::path f = editedField(abc, w / "zero.vdb", [](openvdb::Vec3SGrid& g) {
                 for (auto it = g.beginValueOn(); it; ++it) it.setValue(openvdb::Vec3s(0.0f));
             });
             return bakeArgs(f, w / "out.vdb");
         },
         {"zero"}},
        {"field with a NaN",
         [](const fs::path& w, const fs::path& abc) {
             const fs::path f = editedField(abc, w / "nan.vdb", [](openvdb::Vec3SGrid& g) {
                 const float nan = std::numeric_limits<float>::quiet_NaN();
                 g.tree().setValueOn(openvdb::Coord(5, 6, 7), openvdb::Vec3s(1.0f, nan, 0.0f));
             });
             return bakeArgs(f, w / "out.vdb");
         },
         {"NaN"}},
        {"malformed JSON recipe",
         [](const fs::path& w, const fs::path& abc) {
             writeText(w / "bad.json", "{\"lic\": {\"length\": 5,}");
             return bakeArgs(abc, w / "out.vdb", {"--recipe", (w / "bad.json").string()});
         },
         {"JSON", "bad.json"}},
        {"unknown recipe key",
         [](const fs::path& w, const fs::path& abc) {
             writeText(w / "typo.json", "{\"lic\": {\"lenght\": 5}}");
             return bakeArgs(abc, w / "out.vdb", {"--recipe", (w / "typo.json").string()});
         },
         {"unknown key", "lenght", "did you mean \"length\""}},
        {"--length -1",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--length", "-1"}); },
         {"length", "-1"}},
        {"--step 0",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--step", "0"}); },
         {"step"}},
        {"--upsample 0",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--upsample", "0"}); },
         {"upsample"}},
        {"--engine warp",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--engine", "warp"}); },
         {"engine", "warp"}},
        {"output into a missing directory",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "nodir" / "out.vdb"); },
         {"nodir", "does not exist"}},
        {"unknown preset for field",
         [](const fs::path& w, const fs::path&) {
             return std::vector<std::string>{"field", "nosuchpreset", "--res", "8", "--out", (w / "out.vdb").string()};
         },
         {"nosuchpreset", "abc"}},
        {"unknown flag",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--nosuch"}); },
         {"--nosuch"}},
        {"--field-frames with a field that has no frame number",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--field-frames", "1,3"}); },
         {"--field-frames", "#"}},
        {"a field sequence with a missing frame",
         [](const fs::path& w, const fs::path& abc) {
             fs::copy_file(abc, w / "seq_0001.vdb", fs::copy_options::overwrite_existing);
             fs::copy_file(abc, w / "seq_0003.vdb", fs::copy_options::overwrite_existing);
             return bakeArgs(w / "seq_####.vdb", w / "out.vdb");
         },
         {"frame 2 is missing"}},
        {"a field sequence with a cyclic loop",
         [](const fs::path& w, const fs::path& abc) {
             fs::copy_file(abc, w / "lp_0001.vdb", fs::copy_options::overwrite_existing);
             return bakeArgs(w / "lp_####.vdb", w / "out.vdb", {"--frames", "4"});
         },
         {"animation.frames", "not a loop"}},
        {"--frames 0",
         [](const fs::path& w, const fs::path& abc) { return bakeArgs(abc, w / "out.vdb", {"--frames", "0"}); },
         {"frames"}},
    };
    return cases;
}

class CliBadInputTest : public CliTest, public ::testing::WithParamInterface<std::size_t>
{
};

TEST_P(CliBadInputTest, ExitsTwoNamesProblemWritesNothing)
{
    const BadCase& c = badCases().at(GetParam());
    SCOPED_TRACE(c.name);
    const fs::path abc = makeField("abc.vdb");
    const fs::path w = work();
    const std::vector<std::string> args = c.setup(w, abc);
    ASSERT_FALSE(HasFatalFailure());

    std::set<std::string> before;
    for (const auto& e : fs::recursive_directory_iterator(w)) before.insert(e.path().string());

    const RunResult r = run(args);
    EXPECT_EQ(r.code, 2) << r.describe();
    const std::string err = lower(r.err);
    for (const auto& word : c.words)
        EXPECT_NE(err.find(lower(word)), std::string::npos) << "stderr lacks \"" << word << "\"\n" << r.describe();
    EXPECT_EQ(r.out.find("\"output_voxels\""), std::string::npos) << r.describe();

    // Nothing new: no .vdb, no .json, no temporary file, no directory.
    std::vector<std::string> created;
    for (const auto& e : fs::recursive_directory_iterator(w))
        if (!before.count(e.path().string())) created.push_back(e.path().string());
    EXPECT_TRUE(created.empty()) << "created: " << (created.empty() ? "" : created.front()) << "\n" << r.describe();
    EXPECT_FALSE(fs::exists(w / "out.vdb"));
    EXPECT_FALSE(fs::exists(w / "out.licvdb.json"));
    if (std::getenv("LICVDB_TEST_SHOW_ERRORS")) std::cout << c.name << ":\n" << r.err;
}

INSTANTIATE_TEST_SUITE_P(Cases, CliBadInputTest, ::testing::Range<std::size_t>(0, badCases().size()),
                         [](const ::testing::TestParamInfo<std::size_t>& param) {
                             std::string n;
                             for (char ch : badCases()[param.param].name)
                                 n += std::isalnum(static_cast<unsigned char>(ch)) ? ch : '_';
                             return std::to_string(param.param) + "_" + n;
                         });

// ---- 8. fast vs naive ------------------------------------------------------------------------

TEST_F(CliTest, FastAndNaiveAgree)
{
    const fs::path field = makeField("abc.vdb", "abc", "16,16,16");
    const fs::path of = work("fast.vdb"), on = work("naive.vdb");
    const RunResult rf = bake(field, of, {"--engine", "fast", "--quiet"});
    ASSERT_EQ(rf.code, 0) << rf.describe();
    const RunResult rn = bake(field, on, {"--engine", "naive", "--quiet"});
    ASSERT_EQ(rn.code, 0) << rn.describe();

    auto a = readFloat(of, "density"), b = readFloat(on, "density");
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->metaValue<std::string>("lic_engine"), "fast");
    EXPECT_EQ(b->metaValue<std::string>("lic_engine"), "naive");
    ASSERT_EQ(a->activeVoxelCount(), b->activeVoxelCount());

    auto acc = b->getConstAccessor();
    double n = 0, sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
    for (auto it = a->cbeginValueOn(); it; ++it) {
        float vb = 0;
        ASSERT_TRUE(acc.probeValue(it.getCoord(), vb)) << it.getCoord() << " inactive in the naive bake";
        const double x = *it, y = vb;
        n += 1;
        sa += x;
        sb += y;
        saa += x * x;
        sbb += y * y;
        sab += x * y;
    }
    const double cov = sab / n - (sa / n) * (sb / n);
    const double va = saa / n - (sa / n) * (sa / n), vb = sbb / n - (sb / n) * (sb / n);
    ASSERT_GT(va, 0);
    ASSERT_GT(vb, 0);
    const double corr = cov / std::sqrt(va * vb);
    std::cout << "fast vs naive correlation over " << n << " voxels: " << corr << "\n";
    EXPECT_GT(corr, 0.9);
}

// ---- 9. vdb_print reads the output -----------------------------------------------------------

TEST_F(CliTest, VdbPrintListsDensity)
{
    // scripts/install-deps installs libopenvdb-tools; a missing tool fails rather than skips.
    const char* vdbPrint = "/usr/bin/vdb_print";
    ASSERT_TRUE(fs::exists(vdbPrint)) << vdbPrint << " is not installed (scripts/install-deps installs it)";
    const fs::path field = makeField("abc.vdb");
    const fs::path out = work("lic.vdb");
    ASSERT_EQ(bake(field, out, {"--quiet"}).code, 0);
    const RunResult r = cli_test::runShell(work(), mDir / "logs", std::string(vdbPrint) + " " + cli_test::shellQuote(out.string()));
    const std::string text = r.out + r.err;
    EXPECT_EQ(r.code, 0) << r.describe();
    EXPECT_NE(text.find("density"), std::string::npos) << text;
}

} // namespace

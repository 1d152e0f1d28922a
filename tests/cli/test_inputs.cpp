// Bakes from real inputs, end to end through `licvdb bake`: NumPy, VTK and raw fields keep their
// world position in the output; NaN policy; recipe field keys; and a real Blender (mantaflow)
// smoke simulation cache generated headless by tests/inputs/blender_smoke_cache.py.
#include "InputsHarness.h"

#include "vdbexport/bake/Recipe.h"
#include "vdbexport/io/InputFormats.h"

#include <lic/util/Error.h>

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>

#include <algorithm>
#include <map>

using namespace inputs_test;
using nlohmann::json;

namespace {

std::map<std::string, openvdb::GridBase::Ptr> readAll(const fs::path& p)
{
    std::map<std::string, openvdb::GridBase::Ptr> out;
    openvdb::io::File file(p.string());
    file.open(false);
    for (auto it = file.beginName(); it != file.endName(); ++it) out[it.gridName()] = file.readGrid(it.gridName());
    file.close();
    return out;
}

/// World box of a grid's active voxels (index bbox ± ½ through the transform).
openvdb::BBoxd worldBBox(const openvdb::GridBase& grid)
{
    const openvdb::CoordBBox ib = grid.evalActiveVoxelBoundingBox();
    openvdb::BBoxd out;
    for (int c = 0; c < 8; ++c)
        out.expand(grid.transform().indexToWorld(openvdb::Vec3d((c & 1) ? ib.max()[0] + 0.5 : ib.min()[0] - 0.5,
                                                                (c & 2) ? ib.max()[1] + 0.5 : ib.min()[1] - 0.5,
                                                                (c & 4) ? ib.max()[2] + 0.5 : ib.min()[2] - 0.5)));
    return out;
}

std::string text(const openvdb::BBoxd& b)
{
    std::ostringstream s;
    s << b;
    return s.str();
}

} // namespace

TEST_F(InputsTest, NpyBakeKeepsWorldPosition)
{
    const int X = 10, Y = 8, Z = 6;
    writeBytes(work("swirl.npy"), npy("<f4", "(10, 8, 6, 3)", npyData(X, Y, Z, [](int i, int j, int k) { return swirl(i, j, k, 10, 8); })));
    const RunResult r = run(bakeArgs(work("swirl.npy"), work("out.vdb"),
                                     {"--voxel-size", "0.2", "--origin", "3,-1,2", "--upsample", "2", "--json"}));
    ASSERT_EQ(r.code, 0) << r.describe();
    const json summary = json::parse(r.out);
    EXPECT_EQ(summary["field"]["format"], "npy");
    auto grids = readAll(work("out.vdb"));
    ASSERT_TRUE(grids.count("density"));
    // The field spans voxel centres origin + (0..n-1)·0.2, i.e. world [origin − 0.1, origin + (n − ½)·0.2].
    const openvdb::BBoxd expected(openvdb::Vec3d(3 - 0.1, -1 - 0.1, 2 - 0.1),
                                  openvdb::Vec3d(3 + (X - 0.5) * 0.2, -1 + (Y - 0.5) * 0.2, 2 + (Z - 0.5) * 0.2));
    const openvdb::BBoxd got = worldBBox(*grids["density"]);
    for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(got.min()[a], expected.min()[a], 1e-6) << text(got) << " vs " << text(expected);
        EXPECT_NEAR(got.max()[a], expected.max()[a], 1e-6) << text(got) << " vs " << text(expected);
    }
    EXPECT_NEAR(grids["density"]->voxelSize()[0], 0.1, 1e-9); // upsample 2
    // The resolved recipe records the field keys.
    const json recipe = json::parse(grids["density"]->metaValue<std::string>("licvdb_recipe"));
    EXPECT_EQ(recipe["field"]["voxel_size"], 0.2);
    EXPECT_EQ(recipe["field"]["origin"], json({3.0, -1.0, 2.0}));
    EXPECT_EQ(recipe["field"]["nan_policy"], "refuse");
}

TEST_F(InputsTest, VtiScalarColoursTheBake)
{
    const int n = 6;
    std::string vel, temp;
    for (int k = 0; k < n; ++k) for (int j = 0; j < n; ++j) for (int i = 0; i < n; ++i) {
        const openvdb::Vec3s v = swirl(i, j, k, n, n);
        vel += std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + "\n";
        temp += std::to_string(i) + " ";
    }
    writeBytes(work("f.vti"),
               "<VTKFile type=\"ImageData\" version=\"1.0\"><ImageData WholeExtent=\"0 5 0 5 0 5\" Origin=\"-1 -1 -1\" Spacing=\"0.4 0.4 0.4\">"
               "<Piece Extent=\"0 5 0 5 0 5\"><PointData>"
               "<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"ascii\">" + vel + "</DataArray>"
               "<DataArray type=\"Float32\" Name=\"temperature\" format=\"ascii\">" + temp + "</DataArray>"
               "</PointData></Piece></ImageData></VTKFile>");
    const RunResult r = run(bakeArgs(work("f.vti"), work("out.vdb"), {"--color", "temperature", "--quiet"}));
    ASSERT_EQ(r.code, 0) << r.describe();
    auto grids = readAll(work("out.vdb"));
    ASSERT_TRUE(grids.count("color"));
    const openvdb::BBoxd got = worldBBox(*grids["density"]);
    EXPECT_NEAR(got.min()[0], -1.2, 1e-6);
    EXPECT_NEAR(got.max()[0], -1 + 5.5 * 0.4, 1e-6);
    // Colour follows temperature = i: low x gets the low end of the map, high x the high end.
    const auto color = openvdb::gridPtrCast<openvdb::Vec3SGrid>(grids["color"]);
    const auto scalar = openvdb::gridPtrCast<openvdb::FloatGrid>(grids["scalar"]);
    ASSERT_TRUE(scalar);
    EXPECT_LT(scalar->tree().getValue(openvdb::Coord(0, 3, 3)), 0.05f);
    EXPECT_GT(scalar->tree().getValue(openvdb::Coord(5, 3, 3)), 0.95f);
}

TEST_F(InputsTest, NanPolicyZeroProceedsAndSaysSo)
{
    writeBytes(work("nan.npy"), npy("<f4", "(6, 6, 4, 3)", npyData(6, 6, 4, [](int i, int j, int k) {
        return i == 1 && j == 2 && k == 3 ? openvdb::Vec3s(std::numeric_limits<float>::quiet_NaN()) : swirl(i, j, k, 6, 6);
    })));
    RunResult r = run(bakeArgs(work("nan.npy"), work("out.vdb"), {"--nan-policy", "zero"}));
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_NE(r.err.find("replaced 1 NaN/Inf value(s)"), std::string::npos) << r.describe();
    EXPECT_NE(r.err.find("voxel (1, 2, 3)"), std::string::npos) << r.describe();
    EXPECT_TRUE(fs::exists(work("out.vdb")));
    r = run(bakeArgs(work("nan.npy"), work("out2.vdb"), {"--nan-policy", "zero", "--quiet"}));
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(r.err, "");
}

TEST_F(InputsTest, RawFieldWithRecipeCropAndResample)
{
    writeBytes(work("f.raw"), npyData(12, 12, 8, [](int i, int j, int k) { return swirl(i, j, k, 12, 12); }));
    writeBytes(work("r.json"), R"({"field": {"path": "f.raw", "shape": [12, 12, 8], "dtype": "float32", "voxel_size": 1.0,
                                   "crop": [[2, 2, 0], [9, 9, 7]], "resample": 0.5},
                                   "output": {"path": "out.vdb", "upsample": 1}, "lic": {"length": 4}})");
    const RunResult r = run({"bake", "--recipe", "r.json", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    auto grids = readAll(work("out.vdb"));
    const openvdb::BBoxd got = worldBBox(*grids["density"]);
    // Cropped to centres 2..9 (x, y), resampled at 0.5 starting on the first kept centre.
    EXPECT_NEAR(got.min()[0], 2 - 0.25, 1e-6) << text(got);
    EXPECT_NEAR(got.max()[0], 9 + 0.25, 1e-6) << text(got);
    EXPECT_NEAR(grids["density"]->voxelSize()[0], 0.5, 1e-9);
    const json summary = json::parse(r.out);
    EXPECT_EQ(summary["field"]["notes"].size(), 2u) << summary.dump(2);
}

// A real Blender smoke simulation (Quick Smoke, mantaflow, OpenVDB cache), made headless here.
TEST_F(InputsTest, BlenderSmokeCacheBakes)
{
    const std::string blender = LICVDB_BLENDER_EXE;
    ASSERT_FALSE(blender.empty() || blender.find("NOTFOUND") != std::string::npos)
        << "blender not found at configure time: run scripts/install-deps";
    const std::string script = std::string(LICVDB_SOURCE_DIR) + "/tests/inputs/blender_smoke_cache.py";
    const RunResult b = runCommand(shellQuote(blender) + " -b --factory-startup --python-exit-code 1 -P " + shellQuote(script)
                                   + " -- " + shellQuote(work("cache").string()) + " 3 16");
    ASSERT_EQ(b.code, 0) << b.describe();
    const fs::path cache = work("cache") / "data" / "fluid_data_0003.vdb";
    ASSERT_TRUE(fs::exists(cache)) << b.describe();

    // What mantaflow wrote: a staggered `velocity` (half floats on disk) and `density`.
    auto in = readAll(cache);
    ASSERT_TRUE(in.count("velocity") && in.count("density"));
    EXPECT_EQ(in["velocity"]->getGridClass(), openvdb::GRID_STAGGERED);
    EXPECT_TRUE(in["velocity"]->saveFloatAsHalf());
    const openvdb::BBoxd fieldBox = worldBBox(*in["velocity"]);

    const RunResult r = run({"bake", "--field", cache.string(), "--out", "smoke_lic.vdb", "--length", "6", "--color", "density",
                             "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    const json summary = json::parse(r.out);
    EXPECT_EQ(summary["field"]["grid"], "velocity");
    auto out = readAll(work("smoke_lic.vdb"));
    ASSERT_TRUE(out.count("density") && out.count("color"));
    EXPECT_GT(out["density"]->activeVoxelCount(), 100u);
    const openvdb::BBoxd got = worldBBox(*out["density"]);
    // The bake's density lies within the field's world bounding box (and fills it: same extent).
    const double tol = 1e-5;
    for (int a = 0; a < 3; ++a) {
        EXPECT_GE(got.min()[a], fieldBox.min()[a] - tol) << text(got) << " in " << text(fieldBox);
        EXPECT_LE(got.max()[a], fieldBox.max()[a] + tol) << text(got) << " in " << text(fieldBox);
        EXPECT_NEAR(got.extents()[a], fieldBox.extents()[a], 1e-4) << text(got) << " vs " << text(fieldBox);
    }
    // Output voxel = field voxel / upsample (2).
    EXPECT_NEAR(out["density"]->voxelSize()[0], in["velocity"]->voxelSize()[0] / 2, 1e-9);
}

// A field OpenVDB 13 wrote (VDB format 225: Blender 5's smoke caches and every tool on OpenVDB 13)
// bakes like any other, and without OpenVDB 10's "unsupported VDB file format" warning on stderr
// (licvdb has checked the file: only 13's new half grid type is refused, by name).
TEST_F(InputsTest, OpenVdb13FieldBakesQuietly)
{
    const std::string field = std::string(LICVDB_SOURCE_DIR) + "/tests/inputs/openvdb13/velocity-v225.vdb";
    const RunResult r = run({"bake", "--field", field, "--out", "v13.vdb", "--length", "6", "--color", "density", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_EQ(r.err.find("unsupported"), std::string::npos) << r.describe();
    EXPECT_EQ(r.err.find("WARN"), std::string::npos) << r.describe();
    const json summary = json::parse(r.out);
    EXPECT_EQ(summary["field"]["grid"], "velocity");
    auto out = readAll(work("v13.vdb"));
    ASSERT_TRUE(out.count("density") && out.count("color"));
    EXPECT_EQ(out["density"]->activeVoxelCount(), 32u * 32u * 32u); // 16³ field voxels, upsample 2
    const RunResult info = run({"info", field});
    ASSERT_EQ(info.code, 0) << info.describe();
    EXPECT_EQ(info.err, "") << info.describe();
}

// The input formats are one table (vdbexport/io/InputFormats.h): `licvdb help --json` lists its
// rows, bake's help and the recipe's allowed values name them, and every extension a row lists
// picks that row by path (or an earlier row that shares it: .vtk is dense until its content says mesh).
TEST_F(InputsTest, HelpJsonListsTheInputFormats)
{
    const RunResult r = run({"help", "--json"});
    ASSERT_EQ(r.code, 0) << r.describe();
    json c;
    ASSERT_NO_THROW(c = json::parse(r.out)) << r.describe();
    ASSERT_TRUE(c.contains("formats") && c.at("formats").is_array()) << r.out;
    std::vector<std::string> names;
    for (const auto& f : c.at("formats")) {
        names.push_back(f.at("name").get<std::string>());
        EXPECT_FALSE(f.at("extensions").empty()) << f;
        for (const auto& e : f.at("extensions")) EXPECT_EQ(e.get<std::string>().front(), '.') << f;
        EXPECT_TRUE(f.at("kind") == "grid" || f.at("kind") == "dense" || f.at("kind") == "mesh") << f;
        EXPECT_FALSE(f.at("description").get<std::string>().empty()) << f;
        const auto* row = vdbexport::findInputFormat(names.back());
        ASSERT_NE(row, nullptr) << f;
        EXPECT_EQ(f.at("kind") == "mesh", vdbexport::isMeshFormat(row->name)) << f;
        EXPECT_EQ(f.at("kind") == "dense", row->parse != nullptr) << f;
    }
    EXPECT_EQ(names, (std::vector<std::string>{"vdb", "npy", "vti", "vtk", "raw", "vtu", "vts", "vtm", "vtpc", "pvd",
                                               "vtk-mesh", "plot3d", "openfoam"}));
    const auto raw = std::find_if(c.at("formats").begin(), c.at("formats").end(), [](const json& f) { return f.at("name") == "raw"; });
    EXPECT_EQ(raw->at("extensions"), json({".raw", ".bin", ".dat"}));
    EXPECT_EQ(raw->at("kind"), "dense");
    EXPECT_EQ(raw->at("description"), "a raw binary field file");

    // The recipe accepts "auto" and every name; bake's and convert's --format help list them.
    std::vector<std::string> values{"auto"};
    values.insert(values.end(), names.begin(), names.end());
    EXPECT_EQ(vdbexport::allowedValues("field.format"), values);
    const std::string list = "auto|vdb|npy|vti|vtk|raw|vtu|vts|vtm|vtpc|pvd|vtk-mesh|plot3d|openfoam";
    for (const char* command : {"bake", "convert"}) {
        const RunResult help = run({"help", command});
        EXPECT_NE(help.out.find(list), std::string::npos) << command << "\n" << help.describe();
    }

    // Each extension (any case) picks its row, or the earlier row sharing it.
    for (const auto& f : c.at("formats"))
        for (const auto& e : f.at("extensions")) {
            const std::string ext = e.get<std::string>();
            std::string upper = ext;
            for (auto& ch : upper) ch = char(std::toupper(static_cast<unsigned char>(ch)));
            for (const std::string& path : {"field" + ext, "FIELD" + upper}) {
                const std::string got = vdbexport::formatFromPath(path);
                EXPECT_TRUE(got == f.at("name") || (f.at("name") == "vtk-mesh" && got == "vtk")) << path << ": " << got;
            }
        }
    fs::create_directories(work("case/system"));
    std::ofstream(work("case/system/controlDict")) << "FoamFile {}\n";
    EXPECT_EQ(vdbexport::formatFromPath(work("case").string()), "openfoam");
    EXPECT_EQ(vdbexport::formatFromPath(work("case/system/controlDict").string()), "openfoam");

    // An unknown extension: the message names the file, the extension, every known extension and --format.
    try {
        vdbexport::formatFromPath("field.hdf5");
        ADD_FAILURE() << "field.hdf5 was given a format";
    } catch (const lic::InputError& e) {
        const std::string m = e.what();
        for (const char* part : {"'field.hdf5'", "'.hdf5'", ".raw/.bin/.dat", ".vtpc", ".xyz/.p3d/.x", ".foam", "OpenFOAM case",
                                 "--format vdb|npy|"})
            EXPECT_NE(m.find(part), std::string::npos) << part << " in: " << m;
    }
    // An unknown --format names the known ones (bake refuses it in the recipe already).
    const RunResult bad = run({"convert", work("f.npy").string(), "--format", "hdf5", "--out", work("o.vdb").string()});
    EXPECT_NE(bad.code, 0) << bad.describe();
    EXPECT_NE(bad.err.find("'hdf5'"), std::string::npos) << bad.describe();
    EXPECT_NE(bad.err.find(list), std::string::npos) << bad.describe();
}

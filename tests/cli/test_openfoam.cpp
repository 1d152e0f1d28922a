// Real OpenFOAM runs through `licvdb convert` / `bake` (issue 54 items 1-3): cases made by Debian's
// OpenFOAM v1912 tutorials (tests/openfoam/make_cases.sh, cached in $LICVDB_FOAM_CACHE, default
// /var/cache/licvdb/openfoam). A decomposed run converts to the same field as its reconstructed
// twin at every time; a case with only processor directories reads; `U` beside a stale `U.orig`
// reads U; `--list` says where each time comes from; the honest warnings (zero/uniform velocity,
// only initial conditions: convert writes with a warning, bake exits 2), a time without a velocity
// file, an incomplete processor time, and a case without a mesh (constant/polyMesh, blockMesh,
// decomposePar).
//
// Without OpenFOAM (make_cases.sh exits 77) every test FAILS with "NOT RUN: OpenFOAM not installed"
// unless LICVDB_ALLOW_NO_OPENFOAM=1, which makes them skip with that text.
#include "CellFit.h"
#include "FoamCases.h"
#include "InputsHarness.h"

#include <nlohmann/json.hpp>

#include <openvdb/io/File.h>

#include <vtkDoubleArray.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkOpenFOAMReader.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <regex>

using namespace inputs_test;
using namespace mesh_test;
using namespace foam_test;

namespace {

/// The .vdb's velocity grid.
openvdb::Vec3SGrid::Ptr readVelocity(const fs::path& p)
{
    openvdb::io::File file(p.string());
    file.open();
    auto g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid("velocity"));
    file.close();
    return g;
}

struct GridDiff
{
    std::uint64_t onlyInA = 0, onlyInB = 0, both = 0, nearSeams = 0;
    double maxDiff = 0;      ///< max |a - b| over the voxels active in both, away from the seams
    double maxSeamDiff = 0;  ///< the same near them
    double maxSpeed = 0;     ///< max |a| over the voxels active in both
    bool sameTransform = false;
};

/// Where VTK's own point values of a decomposed case differ from its reconstructed twin's (see
/// expectSameSeries): world position, voxel size -> near such a place.
using SeamFn = std::function<bool(const openvdb::Vec3d&, double)>;

GridDiff compare(const openvdb::Vec3SGrid& a, const openvdb::Vec3SGrid& b, const SeamFn& nearSeam = {})
{
    GridDiff d;
    d.sameTransform = a.transform() == b.transform();
    const double h = a.voxelSize()[0];
    auto bacc = b.getConstAccessor();
    for (auto it = a.cbeginValueOn(); it; ++it) {
        openvdb::Vec3s bv;
        if (!bacc.probeValue(it.getCoord(), bv)) {
            ++d.onlyInA;
            continue;
        }
        ++d.both;
        const double diff = double((*it - bv).length());
        if (nearSeam && nearSeam(a.transform().indexToWorld(it.getCoord()), h)) {
            ++d.nearSeams;
            d.maxSeamDiff = std::max(d.maxSeamDiff, diff);
        } else {
            d.maxDiff = std::max(d.maxDiff, diff);
        }
        d.maxSpeed = std::max(d.maxSpeed, double(it->length()));
    }
    auto aacc = a.getConstAccessor();
    for (auto it = b.cbeginValueOn(); it; ++it)
        if (!aacc.isValueOn(it.getCoord())) ++d.onlyInB;
    return d;
}

class FoamTest : public InputsTest
{
protected:
    void SetUp() override
    {
        InputsTest::SetUp();
        const Cases& c = cases();
        if (c.code == 77) FOAM_TEST_NOT_RUN(kNotRun << "\n" << c.log);
        ASSERT_EQ(c.code, 0) << "tests/openfoam/make_cases.sh " << foamCache() << " failed:\n" << c.log;
    }

    static fs::path foamCase(const std::string& name) { return foamCache() / name; }

    /// A copy of the cached case `name` in the work directory (to change it).
    fs::path copyCase(const std::string& name, const std::string& as = "")
    {
        const fs::path dst = work(as.empty() ? name : as);
        fs::copy(foamCase(name), dst, fs::copy_options::recursive);
        return dst;
    }

    RunResult convert(const fs::path& input, const std::string& out, std::vector<std::string> extra = {})
    {
        std::vector<std::string> args{"convert", input.string(), "--out", out};
        args.insert(args.end(), extra.begin(), extra.end());
        return run(args);
    }

    nlohmann::json listJson(const fs::path& input, std::vector<std::string> extra = {})
    {
        std::vector<std::string> args{"convert", input.string(), "--list", "--json"};
        args.insert(args.end(), extra.begin(), extra.end());
        const RunResult r = run(args);
        EXPECT_EQ(r.code, 0) << r.describe();
        return r.code == 0 ? nlohmann::json::parse(r.out) : nlohmann::json::object();
    }

    /// Convert every time of `a` and `b` (a #### series each) and compare them time by time: the
    /// same lattice and active voxels, values within `tolerance` of the largest speed away from
    /// the seams and within `seamTolerance` of it near them.
    void expectSameSeries(const std::string& a, const std::string& b, std::size_t steps, const SeamFn& nearSeam,
                          double tolerance, double seamTolerance)
    {
        const RunResult ra = convert(foamCase(a), a + "_####.vdb", {"-q"});
        ASSERT_EQ(ra.code, 0) << ra.describe();
        const RunResult rb = convert(foamCase(b), b + "_####.vdb", {"-q"});
        ASSERT_EQ(rb.code, 0) << rb.describe();
        for (std::size_t k = 0; k < steps; ++k) {
            char idx[32];
            std::snprintf(idx, sizeof idx, "%04zu", k);
            SCOPED_TRACE(a + " vs " + b + " step " + idx);
            const auto ga = readVelocity(work(a + "_" + idx + ".vdb"));
            const auto gb = readVelocity(work(b + "_" + idx + ".vdb"));
            ASSERT_TRUE(ga && gb);
            const GridDiff d = compare(*ga, *gb, nearSeam);
            EXPECT_TRUE(d.sameTransform) << "the lattices differ";
            EXPECT_EQ(d.onlyInA, 0u);
            EXPECT_EQ(d.onlyInB, 0u);
            EXPECT_GT(d.both, 1000u);
            EXPECT_LE(d.maxDiff, tolerance * d.maxSpeed) << "max |ΔU| " << d.maxDiff << ", max |U| " << d.maxSpeed;
            EXPECT_LE(d.maxSeamDiff, seamTolerance * d.maxSpeed) << "near the seams: max |ΔU| " << d.maxSeamDiff;
            EXPECT_LE(d.nearSeams, d.both / 3) << "the seams' band is most of the field: the test proves little";
            std::cout << "  " << a << " vs " << b << " step " << idx << ": " << d.both << " voxels, max |U| " << d.maxSpeed
                      << ", max |ΔU| " << d.maxDiff << " (" << d.maxDiff / std::max(d.maxSpeed, 1e-30) << " of max |U|), "
                      << d.nearSeams << " voxels near the seams: max |ΔU| " << d.maxSeamDiff << " ("
                      << d.maxSeamDiff / std::max(d.maxSpeed, 1e-30) << ")\n";
        }
    }
};

bool contains(const std::string& text, const std::string& word) { return lower(text).find(lower(word)) != std::string::npos; }

} // namespace

// The decomposed runs and their reconstructPar twins hold the same cell values (OpenFOAM's
// decomposition is exact; VTK reads the same numbers), and the processors' meshes are merged into
// one, so the fields agree voxel by voxel: measured, max |ΔU| = 0 at every voxel of every time of
// both cases (the cell data fitted from the same cell centres). kTolerance (1e-5 of the largest
// speed) leaves room for float rounding should the fit meet equal neighbours in another order, and
// catches any real difference (a time read from the top level's initial field instead of the
// processors is ~100 % off; a lost processor loses whole voxels). The same holds at the places where
// VTK's own point values differ between the two reads (docs/notes/openfoam-findings.md, section 4),
// which the fit of cell values, band included, does not use: boxTurb16's x = 0 and x = 1 planes (a
// processorCyclic patch when decomposed, a cyclic one, which VTK 9.1 averages one-sidedly, when
// reconstructed: up to 0.0028 with a largest speed of 0.039 in VTK's point values) and the
// TJunction's y = 0 plane, where the processor interface meets the walls (0.09 of 5.5). They are
// reported apart, held to the same tolerance (measured 0 there too).
TEST_F(FoamTest, DecomposedRunConvertsLikeItsReconstructedTwinAtEveryTime)
{
    constexpr double kTolerance = 1e-5, kSeamTolerance = kTolerance;
    const SeamFn boxPlanes = [](const openvdb::Vec3d& p, double h) { return p.x() <= 2 * h || p.x() >= 1 - 2 * h; };
    expectSameSeries("boxTurb16-decomposed", "boxTurb16-reconstructed", 3, boxPlanes, kTolerance, kSeamTolerance);
    const SeamFn interfaceAtWalls = [](const openvdb::Vec3d& p, double h) { return std::abs(p.y()) <= 2 * h; };
    expectSameSeries("TJunction-decomposed", "TJunction-reconstructed", 4, interfaceAtWalls, kTolerance, kSeamTolerance);
    // One mesh: the points the processors share are merged (VTK appends a copy from each).
    for (const std::string c : {"boxTurb16", "TJunction"}) {
        const auto dec = listJson(foamCase(c + "-decomposed")), rec = listJson(foamCase(c + "-reconstructed"));
        EXPECT_EQ(dec["cells"], rec["cells"]) << c;
        EXPECT_EQ(dec["points"], rec["points"]) << c;
        EXPECT_EQ(dec["bounds"], rec["bounds"]) << c;
    }
}

TEST_F(FoamTest, DecomposedRunReadsTheLatestTimeFromTheProcessors)
{
    const RunResult r = convert(foamCase("TJunction-decomposed"), "tj.vdb");
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(contains(r.err, "read time 0.3")) << r.describe();
    EXPECT_TRUE(contains(r.err, "from 2 processor directories (processor0, processor1)")) << r.describe();
    EXPECT_FALSE(contains(r.err, "warning")) << r.describe();
}

TEST_F(FoamTest, ProcessorsOnlyCaseReads)
{
    const RunResult r = convert(foamCase("boxTurb16-processorsOnly"), "only.vdb");
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(contains(r.err, "read time 0.5 of the OpenFOAM case from 2 processor directories")) << r.describe();
    ASSERT_EQ(convert(foamCase("boxTurb16-decomposed"), "dec.vdb", {"-q"}).code, 0);
    const GridDiff d = compare(*readVelocity(work("only.vdb")), *readVelocity(work("dec.vdb")));
    EXPECT_TRUE(d.sameTransform);
    EXPECT_EQ(d.onlyInA + d.onlyInB, 0u);
    EXPECT_EQ(d.maxDiff, 0.0) << "the same processor files";
    const auto j = listJson(foamCase("boxTurb16-processorsOnly"));
    EXPECT_EQ(j["times"], nlohmann::json({0, 0.25, 0.5}));
}

TEST_F(FoamTest, ListShowsWhereTimesComeFrom)
{
    const auto j = listJson(foamCase("boxTurb16-decomposed"));
    EXPECT_EQ(j["times"], nlohmann::json({0, 0.25, 0.5}));
    ASSERT_EQ(j["time_sources"].size(), 3u) << j.dump(2);
    EXPECT_EQ(j["time_sources"][0], "2 processor directories (the top level has it too)");
    EXPECT_EQ(j["time_sources"][1], "2 processor directories");
    EXPECT_EQ(j["time_sources"][2], "2 processor directories");
    EXPECT_EQ(j["time"], 0.5);
    EXPECT_TRUE(j["warnings"].empty()) << j.dump(2);

    const auto serial = listJson(foamCase("TJunction"));
    EXPECT_EQ(serial["time_sources"], nlohmann::json({"the top level", "the top level", "the top level", "the top level"}));

    // A time only the top level has, beside the processors' ones: read from there, and said so.
    const fs::path mixed = copyCase("boxTurb16-decomposed", "mixed");
    fs::copy(foamCase("boxTurb16-reconstructed") / "0.5", mixed / "0.75", fs::copy_options::recursive);
    const RunResult text = run({"convert", mixed.string(), "--list"});
    ASSERT_EQ(text.code, 0) << text.describe();
    EXPECT_TRUE(contains(text.out, "[0] 0 from 2 processor directories (the top level has it too)")) << text.out;
    EXPECT_TRUE(contains(text.out, "[3] 0.75 from the top level (not in the processor directories)")) << text.out;
    const RunResult r = convert(mixed, "mixed.vdb");
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(contains(r.err, "read time 0.75 of the OpenFOAM case from the top level (the processor directories do not have it)"))
        << r.describe();
    const RunResult p = convert(mixed, "mixed05.vdb", {"--time", "0.5"});
    ASSERT_EQ(p.code, 0) << p.describe();
    EXPECT_TRUE(contains(p.err, "from 2 processor directories")) << p.describe();
}

TEST_F(FoamTest, IncompleteProcessorTimeIsAnErrorNamingTheProcessors)
{
    const fs::path c = copyCase("boxTurb16-decomposed", "cut");
    fs::remove_all(c / "processor1" / "0.5");
    const auto j = listJson(c, {"--time", "0.25"});
    ASSERT_EQ(j["time_sources"].size(), 3u);
    EXPECT_EQ(j["time_sources"][2], "incomplete: only in processor0 of 2 processor directories");
    const RunResult r = convert(c, "cut.vdb");
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_TRUE(contains(r.err, "time 0.5 is only in processor0, not in processor1")) << r.describe();
    EXPECT_TRUE(contains(r.err, "--time")) << r.describe();
    EXPECT_FALSE(fs::exists(work("cut.vdb")));
    EXPECT_EQ(convert(c, "cut025.vdb", {"--time", "0.25", "-q"}).code, 0);
}

// U beside a stale U.orig whose header says `object U;`: the field U is the file U, so the
// conversion equals the case without U.orig, bit for bit.
TEST_F(FoamTest, UBesideUOrigReadsU)
{
    const RunResult r = convert(foamCase("boxTurb16-Uorig"), "uorig.vdb", {"--time", "0"});
    ASSERT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(contains(r.err, "left out 0/U.orig (object U)")) << r.describe();
    EXPECT_FALSE(contains(r.err, "warning")) << "U.orig's zeros were read\n" << r.describe();
    ASSERT_EQ(convert(foamCase("boxTurb16"), "plain.vdb", {"--time", "0", "-q"}).code, 0);
    const GridDiff d = compare(*readVelocity(work("uorig.vdb")), *readVelocity(work("plain.vdb")));
    EXPECT_TRUE(d.sameTransform);
    EXPECT_EQ(d.onlyInA + d.onlyInB, 0u);
    EXPECT_GT(d.maxSpeed, 0.01);
    EXPECT_EQ(d.maxDiff, 0.0);
    // --grid picks a file by its name: U.orig itself (all zeros) when asked for.
    const RunResult o = convert(foamCase("boxTurb16-Uorig"), "orig.vdb", {"--time", "0", "--grid", "U.orig"});
    ASSERT_EQ(o.code, 0) << o.describe();
    EXPECT_TRUE(contains(o.err, "warning: the velocity U.orig is zero everywhere at time 0")) << o.describe();
}

// Warnings: convert writes the field and says so on stderr (exit 0); bake refuses (exit 2).
TEST_F(FoamTest, ZeroVelocityWarnsInConvertAndFailsBake)
{
    const RunResult r = convert(foamCase("TJunction"), "zero.vdb", {"--time", "0", "-q"});
    EXPECT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(fs::exists(work("zero.vdb")));
    EXPECT_TRUE(contains(r.err, "warning: the velocity U is zero everywhere at time 0")) << r.describe();
    const RunResult b = run(bakeArgs(foamCase("TJunction"), work("zero_lic.vdb"), {"--time", "0"}));
    EXPECT_EQ(b.code, 2) << b.describe();
    EXPECT_TRUE(contains(b.err, "zero everywhere")) << b.describe();
    EXPECT_TRUE(contains(b.err, "bake refuses")) << b.describe();
    EXPECT_FALSE(fs::exists(work("zero_lic.vdb")));
    // The latest time is a solution: no warning.
    const RunResult ok = convert(foamCase("TJunction"), "latest.vdb");
    EXPECT_EQ(ok.code, 0) << ok.describe();
    EXPECT_FALSE(contains(ok.err, "warning")) << ok.describe();
}

TEST_F(FoamTest, UniformVelocityWarnsInConvertAndFailsBake)
{
    const fs::path c = copyCase("TJunction", "uniform");
    std::string u = readText(c / "0" / "U");
    const auto pos = u.find("internalField   uniform (0 0 0);");
    ASSERT_NE(pos, std::string::npos);
    u.replace(pos, 32, "internalField   uniform (1 2 3);");
    writeBytes(c / "0" / "U", u);
    const RunResult r = convert(c, "uniform.vdb", {"--time", "0"});
    EXPECT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(contains(r.err, "warning: the velocity U is uniform at time 0, (1 2 3) in every cell")) << r.describe();
    const RunResult b = run(bakeArgs(c, work("uniform_lic.vdb"), {"--time", "0"}));
    EXPECT_EQ(b.code, 2) << b.describe();
    EXPECT_TRUE(contains(b.err, "uniform at time 0")) << b.describe();
}

TEST_F(FoamTest, OnlyInitialConditionsWarnsInConvertAndFailsBake)
{
    const fs::path c = work("initial");
    fs::create_directories(c);
    for (const char* d : {"system", "constant", "0"})
        fs::copy(foamCase("boxTurb16") / d, c / d, fs::copy_options::recursive);
    const RunResult r = convert(c, "initial.vdb", {"-q"});
    EXPECT_EQ(r.code, 0) << r.describe();
    EXPECT_TRUE(fs::exists(work("initial.vdb")));
    EXPECT_TRUE(contains(r.err, "warning: the case has only its initial conditions (0/)")) << r.describe();
    const auto j = listJson(c);
    ASSERT_EQ(j["warnings"].size(), 1u) << j.dump(2);
    const RunResult b = run(bakeArgs(c, work("initial_lic.vdb")));
    EXPECT_EQ(b.code, 2) << b.describe();
    EXPECT_TRUE(contains(b.err, "only its initial conditions")) << b.describe();
    EXPECT_FALSE(fs::exists(work("initial_lic.vdb")));

    // A decomposed case that was never run: the same, from the processor directories.
    const fs::path d = copyCase("boxTurb16-decomposed", "notRun");
    for (const char* p : {"processor0", "processor1"})
        for (const char* t : {"0.25", "0.5"}) fs::remove_all(d / p / t);
    const RunResult rd = convert(d, "notRun.vdb", {"-q"});
    EXPECT_EQ(rd.code, 0) << rd.describe();
    EXPECT_TRUE(contains(rd.err, "only its initial conditions (0/ in the processor directories)")) << rd.describe();
}

TEST_F(FoamTest, TimeWithoutVelocityFileSaysSo)
{
    const fs::path c = copyCase("TJunction", "noU");
    fs::remove(c / "0.3" / "U");
    const RunResult r = convert(c, "noU.vdb");
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_TRUE(contains(r.err, "time 0.3 (read from the top level) has no velocity")) << r.describe();
    EXPECT_TRUE(contains(r.err, "times with U: 0, 0.1, 0.2")) << r.describe();
    const RunResult b = run(bakeArgs(c, work("noU_lic.vdb")));
    EXPECT_EQ(b.code, 2) << b.describe();
    EXPECT_TRUE(contains(b.err, "has no velocity")) << b.describe();
    // --list still describes the case, and says it.
    const auto j = listJson(c);
    ASSERT_EQ(j["warnings"].size(), 1u) << j.dump(2);
    EXPECT_TRUE(contains(j["warnings"][0].get<std::string>(), "time 0.3 (read from the top level) has no velocity"));
}

TEST_F(FoamTest, CaseWithoutMeshNamesPolyMeshAndBlockMesh)
{
    const fs::path c = copyCase("boxTurb16", "noMesh");
    fs::remove_all(c / "constant" / "polyMesh");
    const RunResult r = convert(c, "noMesh.vdb");
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_TRUE(contains(r.err, "constant/polyMesh")) << r.describe();
    EXPECT_TRUE(contains(r.err, "blockMesh")) << r.describe();
    EXPECT_FALSE(contains(r.err, "contains no meshes")) << r.describe();

    const fs::path d = copyCase("boxTurb16-processorsOnly", "noProcMesh");
    fs::remove_all(d / "processor1" / "constant" / "polyMesh");
    const RunResult rd = convert(d, "noProcMesh.vdb");
    EXPECT_EQ(rd.code, 2) << rd.describe();
    EXPECT_TRUE(contains(rd.err, "processor1/constant/polyMesh")) << rd.describe();
    EXPECT_TRUE(contains(rd.err, "decomposePar")) << rd.describe();
    EXPECT_TRUE(contains(rd.err, "blockMesh")) << rd.describe();
}

TEST_F(FoamTest, ProcessorDirectoryGivenNamesTheCase)
{
    const RunResult r = run({"convert", (foamCase("boxTurb16-decomposed") / "processor0").string(), "--format", "openfoam",
                             "--out", "p0.vdb"});
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_TRUE(contains(r.err, "is a processor directory of the decomposed OpenFOAM case")) << r.describe();
}

// The shadow cases (symlinks under the temporary directory) go after every read, failed or not.
TEST_F(FoamTest, ShadowCasesAreRemoved)
{
    const fs::path tmp = mDir / "tmp";
    fs::create_directories(tmp);
    auto convertIn = [&](const std::vector<std::string>& args) {
        return runCommand("TMPDIR=" + shellQuote(tmp.string()) + " " + cli_test::licvdbCommand(args));
    };
    EXPECT_EQ(convertIn({"convert", foamCase("boxTurb16-decomposed").string(), "--out", "a.vdb", "-q"}).code, 0);
    EXPECT_EQ(convertIn({"convert", foamCase("TJunction").string(), "--out", "b.vdb", "--grid", "nothere"}).code, 2);
    const fs::path bad = copyCase("TJunction", "badField");
    writeBytes(bad / "0.3" / "p", readText(bad / "0.3" / "p").substr(0, 1500)); // cut inside its values
    const RunResult r = convertIn({"convert", bad.string(), "--out", "c.vdb"});
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_FALSE(contains(r.err, "licvdb-foam-")) << "VTK's message names the shadow, not the case\n" << r.describe();
    EXPECT_TRUE(contains(r.err, (fs::absolute(bad) / "0.3" / "p").string())) << r.describe();
    std::vector<std::string> left;
    for (const auto& e : fs::directory_iterator(tmp)) left.push_back(e.path().string());
    EXPECT_TRUE(left.empty()) << "left behind: " << left.front();
}

TEST_F(FoamTest, PatchWithoutBoundaryFieldEntryIsRefusedNamingIt)
{
    // OpenFOAM refuses a field whose boundaryField lacks a (non-constraint) patch; so do we, naming
    // the file, the patch and its type, rather than reading the field without it.
    const fs::path c = copyCase("TJunction", "noPatch");
    const fs::path u = c / "0.3" / "U";
    std::string text = readText(u);
    const auto at = text.find("    defaultFaces\n    {");
    ASSERT_NE(at, std::string::npos);
    text.erase(at, text.find('}', at) + 1 - at);
    writeBytes(u, text);
    const RunResult r = convert(c, "noPatch.vdb");
    EXPECT_EQ(r.code, 2) << r.describe();
    EXPECT_TRUE(contains(r.err, "0.3/U")) << r.describe();
    EXPECT_TRUE(contains(r.err, "boundaryField has no entry for patch \"defaultFaces\" (type wall")) << r.describe();
    EXPECT_TRUE(contains(r.err, "OpenFOAM would not read this field either")) << r.describe();
    EXPECT_FALSE(fs::exists(work("noPatch.vdb")));
}

/// The internal mesh of an OpenFOAM case with its cell data at the latest time, as VTK reads it
/// (polyhedra kept whole, so each cell is one of the solver's cells).
vtkSmartPointer<vtkDataSet> solverCells(const fs::path& c)
{
    vtkNew<vtkOpenFOAMReader> r;
    r->SetFileName((c / "system" / "controlDict").c_str());
    r->SkipZeroTimeOff();
    r->DecomposePolyhedraOff();
    r->UpdateInformation();
    r->EnableAllCellArrays();
    for (int i = 0; i < r->GetNumberOfPatchArrays(); ++i)
        r->SetPatchArrayStatus(r->GetPatchArrayName(i), std::string(r->GetPatchArrayName(i)) == "internalMesh");
    vtkDoubleArray* tv = r->GetTimeValues();
    if (!tv || tv->GetNumberOfTuples() == 0) return nullptr;
    r->UpdateTimeStep(tv->GetValue(tv->GetNumberOfTuples() - 1));
    auto* blocks = vtkMultiBlockDataSet::SafeDownCast(r->GetOutput());
    if (!blocks || blocks->GetNumberOfBlocks() == 0) return nullptr;
    return vtkDataSet::SafeDownCast(blocks->GetBlock(0));
}

TEST_F(FoamTest, RealCasesReadBackAtTheCellCentres)
{
    // Issue 54's bar, at the default voxel size and at 0.87 of it (lattice points off the cell
    // centres): >= 99 % of random points inside the cells have their 8 trilinear corners active,
    // >= 99 % of the cell centres too, and there the field is within 10 % of each cell's own value on
    // average, its mean speed within 5 % of the cells'.
    for (const char* name : {"TJunction", "pipeCyclic", "boxTurb16"}) {
        SCOPED_TRACE(name);
        const fs::path c = foamCase(name);
        const auto mesh = solverCells(c);
        ASSERT_TRUE(mesh);
        vdbexport::FieldSpec spec;
        spec.path = c.string();
        const auto f = vdbexport::loadField(spec);
        ASSERT_TRUE(f.velocity);
        for (double scale : {1.0, 0.87}) {
            SCOPED_TRACE(scale);
            vdbexport::LoadedField scaled;
            if (scale != 1.0) {
                spec.voxelSize = scale * f.velocity->voxelSize()[0];
                scaled = vdbexport::loadField(spec);
            }
            const auto& g = scale == 1.0 ? f : scaled;
            const CellFit fit = fitToCells(*g.velocity, mesh, "U");
            printFit(std::string(name) + " (" + (scale == 1.0 ? "default voxel size" : "0.87 x the default") + ")", g, fit);
            EXPECT_GE(fit.pointsCovered, 0.99);
            EXPECT_GE(fit.centresCovered, 0.99);
            EXPECT_LE(fit.relError, 0.10);
            EXPECT_NEAR(fit.speedRatio, 1.0, 0.05);
        }
    }
}

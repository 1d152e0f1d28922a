// Golden digests: the SHA-256 of every grid of a fixed set of bakes (noise; spots with halos, three
// widths, colour and tangent; a box loop; an exp loop; unsteady noise and spot sequences; a naive
// bake; the same noise bake over 3 MPI ranks) and of a rendered PNG's pixels, against the digests
// recorded in tests/golden/digests.json. They pin the product's output bit for bit, so a change
// meant to leave behaviour alone (a restructuring, a refactor) proves it did.
//
// Two digests per grid: `data` (name, class, value type, transform, background, every leaf's
// origin, mask and values, every tile) and `meta` (the grid's metadata as text). A change that
// is meant to change the output re-records them: LICVDB_GOLDEN_UPDATE=1 writes the file anew
// (then say why in the commit, and check the accuracy tests still pass).
#include <gtest/gtest.h>

#include "CliRun.h"
#include "../unit/TempDirSuite.h"
#include "vdbexport/io/Sha256.h"

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
using nlohmann::json;
using cli_test::RunResult;

namespace {

const fs::path kGoldenFile = fs::path(LICVDB_SOURCE_DIR) / "tests" / "golden" / "digests.json";

template<typename T>
void hashValue(vdbexport::Sha256& h, const T& v)
{
    h.update(&v, sizeof v);
}

void hashText(vdbexport::Sha256& h, const std::string& s)
{
    const std::uint64_t n = s.size();
    hashValue(h, n);
    h.update(s.data(), s.size());
}

template<typename GridT>
std::string dataDigest(const GridT& grid)
{
    using ValueT = typename GridT::ValueType;
    vdbexport::Sha256 h;
    hashText(h, grid.getName());
    hashText(h, grid.type());
    hashText(h, openvdb::GridBase::gridClassToString(grid.getGridClass()));
    const openvdb::Mat4d m = grid.transform().baseMap()->getAffineMap()->getMat4();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) hashValue(h, m(i, j));
    hashValue(h, grid.background());
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        hashValue(h, leaf->origin());
        const auto& mask = leaf->getValueMask();
        for (openvdb::Index w = 0; w < mask.WORD_COUNT; ++w) hashValue(h, mask.template getWord<openvdb::Index64>(w));
        h.update(leaf->buffer().data(), sizeof(ValueT) * leaf->SIZE);
    }
    for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
        if (it.isVoxelValue()) continue;
        hashValue(h, it.getCoord());
        hashValue(h, it.getDepth());
        hashValue(h, it.isValueOn());
        hashValue(h, *it);
    }
    return h.hex();
}

std::string metaDigest(const openvdb::GridBase& grid)
{
    vdbexport::Sha256 h;
    for (auto it = grid.beginMeta(); it != grid.endMeta(); ++it) {
        hashText(h, it->first);
        hashText(h, it->second->typeName());
        hashText(h, it->second->str());
    }
    return h.hex();
}

/// {grid name: {data, meta}} of every grid in a .vdb file.
json fileDigests(const fs::path& path)
{
    openvdb::io::File file(path.string());
    file.open();
    json out = json::object();
    const openvdb::GridPtrVecPtr grids = file.getGrids();
    for (const auto& base : *grids) {
        std::string data;
        if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(base)) data = dataDigest(*f);
        else if (auto v = openvdb::GridBase::grid<openvdb::Vec3SGrid>(base)) data = dataDigest(*v);
        else ADD_FAILURE() << path << ": grid " << base->getName() << " has unexpected type " << base->type();
        out[base->getName()] = {{"data", data}, {"meta", metaDigest(*base)}};
    }
    file.close();
    return out;
}

/// SHA-256 of an image's pixels (as 8-bit channels, with its size), read with OIIO.
std::string pixelDigest(const fs::path& path)
{
    auto in = OIIO::ImageInput::open(path.string());
    if (!in) return "unreadable: " + OIIO::geterror();
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<unsigned char> pixels(std::size_t(spec.width) * spec.height * spec.nchannels);
    in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, pixels.data());
    in->close();
    vdbexport::Sha256 h;
    hashValue(h, spec.width);
    hashValue(h, spec.height);
    hashValue(h, spec.nchannels);
    h.update(pixels.data(), pixels.size());
    return h.hex();
}

class Golden : public lictest::TempDirSuite<Golden>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("golden", "logs");
        must({"field", "abc", "--res", "16,16,16", "--out", "abc.vdb", "--quiet"});
        must({"field", "tabbed-jet", "--res", "20,20,28", "--out", "jet.vdb", "--quiet"});
        must({"field", "uniform", "--res", "16,12,12", "--out", "uniform.vdb", "--quiet"});
        must({"field", "tornado", "--res", "16,16,16", "--frames", "1,3", "--out", "tornado_####.vdb", "--quiet"});
        std::ifstream in(kGoldenFile);
        if (in) sGolden = json::parse(in);
    }
    static void TearDownTestSuite()
    {
        if (std::getenv("LICVDB_GOLDEN_UPDATE")) {
            std::ofstream(kGoldenFile) << sRecorded.dump(2) << "\n";
            std::cerr << "recorded the golden digests in " << kGoldenFile << "\n";
        }
        TempDirSuite::TearDownTestSuite();
    }

    static RunResult run(const std::vector<std::string>& args) { return cli_test::runLicvdb(sDir, sDir / "logs", args); }
    static void must(const std::vector<std::string>& args)
    {
        const RunResult r = run(args);
        ASSERT_EQ(r.code, 0) << r.describe();
    }

    /// Bake `args` into OUT (relative to the suite's directory, so the recorded recipe is the same
    /// on every machine) and compare every grid of `files` with the golden digests of `name`.
    void expectGolden(const std::string& name, const std::vector<std::string>& files)
    {
        json got = json::object();
        for (const auto& f : files) {
            ASSERT_TRUE(fs::exists(sDir / f)) << f;
            got[f] = fileDigests(sDir / f);
        }
        sRecorded[name] = got;
        if (std::getenv("LICVDB_GOLDEN_UPDATE")) return;
        ASSERT_TRUE(sGolden.contains(name)) << "no golden digests for \"" << name << "\" in " << kGoldenFile
                                            << "; record them with LICVDB_GOLDEN_UPDATE=1";
        const json& want = sGolden[name];
        EXPECT_EQ(got.size(), want.size()) << name << ": files " << got.dump() << " vs " << want.dump();
        for (const auto& [file, grids] : want.items()) {
            ASSERT_TRUE(got.contains(file)) << name << ": " << file << " was not written";
            EXPECT_EQ(got[file].size(), grids.size()) << name << "/" << file << ": grids " << got[file].dump();
            for (const auto& [grid, d] : grids.items()) {
                ASSERT_TRUE(got[file].contains(grid)) << name << "/" << file << ": no grid " << grid;
                EXPECT_EQ(got[file][grid]["data"], d["data"]) << name << "/" << file << ": grid " << grid << " data differs";
                EXPECT_EQ(got[file][grid]["meta"], d["meta"]) << name << "/" << file << ": grid " << grid << " metadata differs";
            }
        }
    }

    static json sGolden, sRecorded;
};

json Golden::sGolden, Golden::sRecorded = json::object();

TEST_F(Golden, NoiseWithColourInputAndTangent)
{
    must({"bake", "--field", "abc.vdb", "--out", "noise.vdb", "--length", "8", "--color", "vorticity", "--colormap",
          "heated-object", "--write-input", "--write-tangent", "--quiet"});
    expectGolden("noise", {"noise.vdb"});
}

TEST_F(Golden, NaiveNoiseWithPostRegion)
{
    must({"bake", "--field", "abc.vdb", "--out", "naive.vdb", "--engine", "naive", "--length", "5", "--roi", "speed",
          "--roi-range", "1,3", "--roi-mode", "post", "--quiet"});
    expectGolden("naive", {"naive.vdb"});
}

TEST_F(Golden, SpotsHalosThreeWidthsColourTangent)
{
    must({"bake", "--field", "jet.vdb", "--out", "spots.vdb", "--input", "spots", "--spacing", "5", "--radii", "1,1.5,2",
          "--width", "speed", "--width-invert", "--color", "temperature", "--colormap", "red-yellow", "--write-tangent",
          "--write-series", "--length", "10", "--quiet"});
    expectGolden("spots", {"spots.vdb"});
}

TEST_F(Golden, GatherSpotsWithPreRegionAndInput)
{
    must({"bake", "--field", "jet.vdb", "--out", "gather.vdb", "--input", "spots", "--engine", "fast", "--spacing", "5",
          "--roi", "speed", "--roi-range", "0.3,2", "--write-input", "--length", "8", "--quiet"});
    expectGolden("gather_spots", {"gather.vdb"});
}

TEST_F(Golden, BoxNoiseLoop)
{
    must({"bake", "--field", "abc.vdb", "--out", "box.vdb", "--length", "6", "--frames", "3", "--quiet"});
    expectGolden("box_loop", {"box_0001.vdb", "box_0002.vdb", "box_0003.vdb"});
}

TEST_F(Golden, ExpSpotLoop)
{
    must({"bake", "--field", "uniform.vdb", "--out", "exp.vdb", "--input", "spots", "--spacing", "6", "--kernel", "exp",
          "--decay", "0.85", "--length", "8", "--frames", "3", "--quiet"});
    expectGolden("exp_loop", {"exp_0001.vdb", "exp_0002.vdb", "exp_0003.vdb"});
}

TEST_F(Golden, ExpNoiseLoop)
{
    must({"bake", "--field", "abc.vdb", "--out", "expn.vdb", "--kernel", "exp", "--length", "6", "--frames", "2",
          "--quiet"});
    expectGolden("exp_noise_loop", {"expn_0001.vdb", "expn_0002.vdb"});
}

TEST_F(Golden, UnsteadyNoiseSequence)
{
    must({"bake", "--field", "tornado_####.vdb", "--field-frames", "1,3", "--out", "seq.vdb", "--length", "6", "--quiet"});
    expectGolden("unsteady_noise", {"seq_0001.vdb", "seq_0002.vdb", "seq_0003.vdb"});
}

TEST_F(Golden, UnsteadySpotSequence)
{
    must({"bake", "--field", "tornado_####.vdb", "--field-frames", "1,3", "--out", "sseq.vdb", "--input", "spots",
          "--spacing", "5", "--length", "6", "--quiet"});
    expectGolden("unsteady_spots", {"sseq_0001.vdb", "sseq_0002.vdb", "sseq_0003.vdb"});
}

#ifdef LICVDB_MPIEXEC
TEST_F(Golden, ThreeRanksGiveTheOneProcessDigests)
{
    const std::vector<std::string> args{"bake", "--field", "abc.vdb", "--length", "8", "--brick", "16", "--color", "speed",
                                        "--quiet"};
    std::vector<std::string> one = args, three = args;
    one.insert(one.end(), {"--out", "np1.vdb"});
    three.insert(three.end(), {"--out", "np3.vdb"});
    must(one);
    const RunResult r = cli_test::runShell(sDir, sDir / "logs",
                                           cli_test::shellQuote(LICVDB_MPIEXEC) +
                                               " --allow-run-as-root --oversubscribe -np 3 " + cli_test::licvdbCommand(three));
    ASSERT_EQ(r.code, 0) << r.describe();
    // The recipe in the metadata names its output: compare the data digests across the two, and
    // the one-process file's whole digests with the golden ones.
    const json a = fileDigests(sDir / "np1.vdb"), b = fileDigests(sDir / "np3.vdb");
    ASSERT_EQ(a.size(), b.size());
    for (const auto& [grid, d] : a.items()) EXPECT_EQ(b[grid]["data"], d["data"]) << grid;
    expectGolden("mpi", {"np1.vdb"});
}
#endif

TEST_F(Golden, RenderedPng)
{
    must({"bake", "--field", "jet.vdb", "--out", "halos.vdb", "--input", "spots", "--spacing", "6", "--length", "8",
          "--color", "temperature", "--quiet"});
    must({"render", "halos.vdb", "--out", "halos.png", "--size", "96,72", "--quiet"});
    const std::string got = pixelDigest(sDir / "halos.png");
    sRecorded["render_png"] = got;
    if (std::getenv("LICVDB_GOLDEN_UPDATE")) return;
    ASSERT_TRUE(sGolden.contains("render_png")) << "record the golden digests with LICVDB_GOLDEN_UPDATE=1";
    EXPECT_EQ(got, sGolden["render_png"].get<std::string>());
}

} // namespace

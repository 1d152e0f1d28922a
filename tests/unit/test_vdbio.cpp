// Tests of vdbexport/io/VdbIO.h and vdbexport/io/Info.h: reading velocity and scalar grids, the error
// messages for bad files, atomic writes, and `licvdb info`'s description.
#include <gtest/gtest.h>

#include "TempDirSuite.h"

#include "vdbexport/io/Info.h"
#include "vdbexport/io/AtomicWrite.h"
#include "vdbexport/io/FieldGrids.h"
#include "vdbexport/io/VdbReader.h"
#include "vdbexport/io/VdbWrite.h"
#include "vdbexport/io/SealedLeaves.h"
#include "io/VdbGridReader.h"

#include <lic/util/Error.h>

#include <openvdb/openvdb.h>
#include <tbb/parallel_for.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <type_traits>
#include <utility>


namespace fs = std::filesystem;
using vdbexport::describeVdb;
using vdbexport::formatInfo;
using vdbexport::readScalarGrids;
using vdbexport::readVelocityGrid;
using vdbexport::writeTextAtomic;
using vdbexport::writeVdbAtomic;

namespace {

class VdbIOTest : public lictest::TempDirTest
{
protected:
    std::string file(const std::string& name) const { return (mDir / name).string(); }

    /// Names of files in the test directory that contain ".tmp-".
    std::vector<std::string> tempFiles() const
    {
        std::vector<std::string> out;
        for (const auto& e : fs::directory_iterator(mDir))
            if (e.path().filename().string().find(".tmp-") != std::string::npos)
                out.push_back(e.path().filename().string());
        return out;
    }
};

/// A Vec3 grid named `name` with a few distinct active values; the value at (i,j,k) is `f(i,j,k)`.
template<typename GridT = openvdb::Vec3SGrid>
typename GridT::Ptr makeVec3Grid(const std::string& name, double scale = 1.0, double voxelSize = 0.5)
{
    using V = typename GridT::ValueType;
    using E = typename V::value_type;
    auto grid = GridT::create(V(E(0)));
    grid->setName(name);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(voxelSize));
    grid->transform().postTranslate(openvdb::Vec3d(1.0, -2.0, 3.0));
    grid->setGridClass(openvdb::GRID_STAGGERED);
    auto acc = grid->getAccessor();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 2; ++k)
                acc.setValue(openvdb::Coord(i, j, k),
                             V(E(scale * (i + 0.25)), E(scale * (j - 1.5)), E(scale * (k + 0.125))));
    return grid;
}

openvdb::FloatGrid::Ptr makeFloatGrid(const std::string& name, float value = 2.5f)
{
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    grid->getAccessor().setValue(openvdb::Coord(1, 2, 3), value);
    grid->getAccessor().setValue(openvdb::Coord(-4, 0, 7), -value);
    return grid;
}

/// A float grid with many distinct values, so that its file is large enough to cut.
openvdb::FloatGrid::Ptr makeBigFloatGrid(const std::string& name)
{
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    auto acc = grid->getAccessor();
    for (int i = 0; i < 40; ++i)
        for (int j = 0; j < 40; ++j)
            for (int k = 0; k < 40; ++k)
                acc.setValue(openvdb::Coord(i, j, k), std::sin(0.37f * i + 1.3f * j * k) + 0.001f * k);
    return grid;
}

void writeText(const std::string& path, const std::string& text)
{
    std::ofstream(path, std::ios::binary) << text;
}

std::string readFile(const std::string& path)
{
    std::string bytes(static_cast<std::size_t>(fs::file_size(path)), '\0');
    std::ifstream in(path, std::ios::binary);
    in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return bytes;
}

/// Run `fn`, expect a lic::InputError, and return its message.
std::string inputErrorOf(const std::function<void()>& fn)
{
    try {
        fn();
    } catch (const lic::InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected lic::InputError, got another exception: " << e.what();
        return {};
    }
    ADD_FAILURE() << "expected lic::InputError, nothing was thrown";
    return {};
}

#define EXPECT_CONTAINS(haystack, needle) \
    EXPECT_NE(std::string(haystack).find(needle), std::string::npos) \
        << "expected \"" << (needle) << "\" in: " << (haystack)

} // namespace

// ---- reading velocity grids -----------------------------------------------------------------

TEST_F(VdbIOTest, RoundTripKeepsValuesTransformNameAndClass)
{
    auto grid = makeVec3Grid("velocity");
    grid->insertMeta("note", openvdb::StringMetadata("hello"));
    const std::string path = file("field.vdb");
    writeVdbAtomic(path, {grid});

    std::string chosen;
    auto back = readVelocityGrid(path, "", &chosen);
    ASSERT_TRUE(back);
    EXPECT_EQ(chosen, "velocity");
    EXPECT_EQ(back->getName(), "velocity");
    EXPECT_EQ(back->getGridClass(), openvdb::GRID_STAGGERED);
    EXPECT_EQ(back->transform(), grid->transform());
    EXPECT_EQ(back->activeVoxelCount(), grid->activeVoxelCount());
    EXPECT_EQ(back->metaValue<std::string>("note"), "hello");
    for (auto it = grid->cbeginValueOn(); it; ++it)
        EXPECT_EQ(back->tree().getValue(it.getCoord()), *it) << "at " << it.getCoord();
}

TEST_F(VdbIOTest, DefaultNamePrefersVelocityOverVel)
{
    const std::string path = file("both.vdb");
    // `vel` comes first in the file; `velocity` must still win.
    writeVdbAtomic(path, {makeVec3Grid("vel", 1.0), makeVec3Grid("velocity", 10.0), makeVec3Grid("v", 100.0)});
    std::string chosen;
    auto grid = readVelocityGrid(path, "", &chosen);
    EXPECT_EQ(chosen, "velocity");
    EXPECT_EQ(grid->getName(), "velocity");
    EXPECT_FLOAT_EQ(grid->tree().getValue(openvdb::Coord(0, 0, 0)).x(), 2.5f);
}

TEST_F(VdbIOTest, DefaultNameVelPreferredOverV)
{
    const std::string path = file("velv.vdb");
    writeVdbAtomic(path, {makeVec3Grid("v", 100.0), makeVec3Grid("vel", 1.0), makeFloatGrid("density")});
    std::string chosen;
    readVelocityGrid(path, "", &chosen);
    EXPECT_EQ(chosen, "vel");
}

TEST_F(VdbIOTest, DefaultNameVelAlone)
{
    const std::string path = file("vel.vdb");
    writeVdbAtomic(path, {makeFloatGrid("density"), makeVec3Grid("vel")});
    std::string chosen;
    auto grid = readVelocityGrid(path, "", &chosen);
    EXPECT_EQ(chosen, "vel");
    EXPECT_EQ(grid->getName(), "vel");
}

TEST_F(VdbIOTest, DefaultNameSkipsNonVec3GridCalledVelocity)
{
    const std::string path = file("floatvelocity.vdb");
    writeVdbAtomic(path, {makeFloatGrid("velocity"), makeVec3Grid("wind")});
    std::string chosen;
    readVelocityGrid(path, "", &chosen);
    EXPECT_EQ(chosen, "wind");
}

TEST_F(VdbIOTest, DefaultNameSingleOddlyNamedVec3Grid)
{
    const std::string path = file("wind.vdb");
    writeVdbAtomic(path, {makeFloatGrid("density"), makeVec3Grid("wind"), makeFloatGrid("temperature")});
    std::string chosen;
    auto grid = readVelocityGrid(path, "", &chosen);
    EXPECT_EQ(chosen, "wind");
    EXPECT_EQ(grid->activeVoxelCount(), 24u);
}

TEST_F(VdbIOTest, TwoOddlyNamedVec3GridsIsAnErrorListingBoth)
{
    const std::string path = file("two.vdb");
    writeVdbAtomic(path, {makeVec3Grid("wind"), makeVec3Grid<openvdb::Vec3DGrid>("flow"), makeFloatGrid("density")});
    const std::string msg = inputErrorOf([&] { readVelocityGrid(path); });
    EXPECT_CONTAINS(msg, "wind (vec3s)");
    EXPECT_CONTAINS(msg, "flow (vec3d)");
    EXPECT_CONTAINS(msg, "--grid NAME");
    EXPECT_CONTAINS(msg, path);
    EXPECT_EQ(msg.find("density"), std::string::npos) << msg;
}

TEST_F(VdbIOTest, ExplicitNameChoosesThatGrid)
{
    const std::string path = file("named.vdb");
    writeVdbAtomic(path, {makeVec3Grid("velocity", 1.0), makeVec3Grid("flow", 10.0)});
    std::string chosen;
    auto grid = readVelocityGrid(path, "flow", &chosen);
    EXPECT_EQ(chosen, "flow");
    EXPECT_FLOAT_EQ(grid->tree().getValue(openvdb::Coord(1, 0, 0)).x(), 12.5f);
}

TEST_F(VdbIOTest, Vec3dGridIsConvertedKeepingTransformClassAndMetadata)
{
    auto grid = makeVec3Grid<openvdb::Vec3DGrid>("velocity", 3.0, 0.25);
    grid->insertMeta("units", openvdb::StringMetadata("m/s"));
    grid->tree().addTile(/*level=*/1, openvdb::Coord(64, 0, 0), openvdb::Vec3d(1.5, 2.5, -3.5), true);
    grid->tree().setValueOff(openvdb::Coord(7, 7, 7), openvdb::Vec3d(0.5, 0.25, 0.125));
    grid->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    const std::string path = file("double.vdb");
    openvdb::io::File(path).write({grid}); // plain OpenVDB, so the tile stays a tile

    auto back = readVelocityGrid(path);
    ASSERT_TRUE(back);
    EXPECT_EQ(back->valueType(), "vec3s");
    EXPECT_EQ(back->getName(), "velocity");
    EXPECT_EQ(back->getGridClass(), openvdb::GRID_STAGGERED);
    EXPECT_EQ(back->getVectorType(), openvdb::VEC_CONTRAVARIANT_RELATIVE);
    EXPECT_EQ(back->metaValue<std::string>("units"), "m/s");
    EXPECT_EQ(back->transform(), grid->transform());
    EXPECT_EQ(back->activeVoxelCount(), grid->activeVoxelCount());
    EXPECT_EQ(back->tree().activeTileCount(), 1u);
    for (auto it = grid->cbeginValueOn(); it; ++it) {
        const openvdb::Vec3s v = back->tree().getValue(it.getCoord());
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(v[c], static_cast<float>((*it)[c])) << it.getCoord();
    }
    EXPECT_EQ(back->tree().getValue(openvdb::Coord(70, 3, 5)), openvdb::Vec3s(1.5f, 2.5f, -3.5f));
    // Inactive values inside leaves matter to interpolation near the active boundary.
    EXPECT_FALSE(back->tree().isValueOn(openvdb::Coord(7, 7, 7)));
    EXPECT_EQ(back->tree().getValue(openvdb::Coord(7, 7, 7)), openvdb::Vec3s(0.5f, 0.25f, 0.125f));
}

// ---- error cases ----------------------------------------------------------------------------

TEST_F(VdbIOTest, MissingFileIsInputErrorNamingThePath)
{
    const std::string path = file("nope.vdb");
    for (const auto& msg : {inputErrorOf([&] { readVelocityGrid(path); }),
                            inputErrorOf([&] { readScalarGrids(path); }),
                            inputErrorOf([&] { describeVdb(path); })}) {
        EXPECT_CONTAINS(msg, path);
        EXPECT_CONTAINS(msg, "not found");
    }
}

TEST_F(VdbIOTest, DirectoryIsInputError)
{
    const std::string msg = inputErrorOf([&] { readVelocityGrid(mDir.string()); });
    EXPECT_CONTAINS(msg, mDir.string());
    EXPECT_CONTAINS(msg, "directory");
}

TEST_F(VdbIOTest, EmptyFileIsInputError)
{
    const std::string path = file("empty.vdb");
    writeText(path, "");
    const std::string msg = inputErrorOf([&] { readVelocityGrid(path); });
    EXPECT_CONTAINS(msg, path);
    EXPECT_CONTAINS(msg, "empty");
}

TEST_F(VdbIOTest, TextFileIsInputError)
{
    const std::string path = file("notes.vdb");
    writeText(path, "this is not a volume, just some text that is long enough to have a header\n");
    for (const auto& msg : {inputErrorOf([&] { readVelocityGrid(path); }),
                            inputErrorOf([&] { describeVdb(path); })}) {
        EXPECT_CONTAINS(msg, path);
        EXPECT_CONTAINS(msg, "not an OpenVDB file");
    }
}

TEST_F(VdbIOTest, TruncatedFileIsInputErrorAtAnyCut)
{
    const std::string whole = file("whole.vdb");
    writeVdbAtomic(whole, {makeBigFloatGrid("density"), makeVec3Grid("velocity")});
    const std::string bytes = readFile(whole);
    ASSERT_GT(bytes.size(), 1000u);
    // Every cut inside the header and grid table, then cuts through the grid data, including
    // one byte short of the end (OpenVDB alone reads that without complaint).
    std::vector<std::size_t> cuts;
    for (std::size_t n = 1; n < 200; ++n) cuts.push_back(n);
    for (const double fraction : {0.1, 0.25, 0.5, 0.75, 0.9, 0.99})
        cuts.push_back(static_cast<std::size_t>(fraction * static_cast<double>(bytes.size())));
    cuts.push_back(bytes.size() - 1);
    const std::string path = file("cut.vdb");
    for (const std::size_t cut : cuts) {
        SCOPED_TRACE("cut at byte " + std::to_string(cut) + " of " + std::to_string(bytes.size()));
        writeText(path, bytes.substr(0, cut));
        for (const auto& msg : {inputErrorOf([&] { readVelocityGrid(path); }),
                                inputErrorOf([&] { readScalarGrids(path); }),
                                inputErrorOf([&] { describeVdb(path); })}) {
            EXPECT_CONTAINS(msg, path);
            EXPECT_CONTAINS(msg, "truncated");
        }
    }
    const std::string msg = inputErrorOf([&] { readVelocityGrid(path); });
    EXPECT_CONTAINS(msg, "grid 'velocity' should end at byte " + std::to_string(bytes.size()));
}

TEST_F(VdbIOTest, CorruptGridDataIsInputErrorOrReadsButNeverCrashes)
{
    const std::string whole = file("whole.vdb");
    writeVdbAtomic(whole, {makeBigFloatGrid("density")});
    const std::string bytes = readFile(whole);
    const std::string path = file("corrupt.vdb");
    for (const double at : {0.1, 0.3, 0.5, 0.7, 0.9}) {
        SCOPED_TRACE("garbage at " + std::to_string(at));
        std::string damaged = bytes;
        const auto start = static_cast<std::size_t>(at * static_cast<double>(damaged.size()));
        for (std::size_t i = start; i < std::min(start + 512, damaged.size()); ++i)
            damaged[i] = static_cast<char>((i * 131) ^ 0x5a);
        writeText(path, damaged);
        try {
            describeVdb(path);
        } catch (const lic::InputError& e) {
            EXPECT_CONTAINS(std::string(e.what()), path);
        }
    }
}

TEST_F(VdbIOTest, NamedGridNotPresentListsTheGridsThatAre)
{
    const std::string path = file("grids.vdb");
    writeVdbAtomic(path, {makeFloatGrid("density"), makeVec3Grid("vel")});
    const std::string msg = inputErrorOf([&] { readVelocityGrid(path, "velocity"); });
    EXPECT_CONTAINS(msg, "'velocity' not found");
    EXPECT_CONTAINS(msg, path);
    EXPECT_CONTAINS(msg, "density (float)");
    EXPECT_CONTAINS(msg, "vel (vec3s)");
}

TEST_F(VdbIOTest, NamedGridOfWrongTypeSaysItsType)
{
    const std::string path = file("grids.vdb");
    writeVdbAtomic(path, {makeFloatGrid("density"), makeVec3Grid("vel")});
    const std::string msg = inputErrorOf([&] { readVelocityGrid(path, "density"); });
    EXPECT_CONTAINS(msg, "'density'");
    EXPECT_CONTAINS(msg, "a float grid cannot be a velocity field");
}

TEST_F(VdbIOTest, NoVec3GridIsInputError)
{
    const std::string path = file("scalars.vdb");
    writeVdbAtomic(path, {makeFloatGrid("density"), makeFloatGrid("temperature")});
    const std::string msg = inputErrorOf([&] { readVelocityGrid(path); });
    EXPECT_CONTAINS(msg, "no Vec3 grid");
    EXPECT_CONTAINS(msg, "density (float)");
    EXPECT_CONTAINS(msg, "temperature (float)");
}

// ---- scalar grids ---------------------------------------------------------------------------

TEST_F(VdbIOTest, ReadScalarGridsConvertsDoubleAndHalfAndSkipsVectors)
{
    auto f = makeFloatGrid("temperature", 2.5f);
    auto d = openvdb::DoubleGrid::create(0.0);
    d->setName("pressure");
    d->getAccessor().setValue(openvdb::Coord(5, 6, 7), 1.25);
    auto h = makeFloatGrid("density", 0.75f);
    h->setSaveFloatAsHalf(true);
    const std::string path = file("scalars.vdb");
    writeVdbAtomic(path, {f, d, h, makeVec3Grid("velocity")});

    const auto grids = readScalarGrids(path);
    ASSERT_EQ(grids.size(), 3u);
    ASSERT_TRUE(grids.count("temperature") && grids.count("pressure") && grids.count("density"));
    EXPECT_FLOAT_EQ(grids.at("temperature")->tree().getValue(openvdb::Coord(1, 2, 3)), 2.5f);
    EXPECT_FLOAT_EQ(grids.at("pressure")->tree().getValue(openvdb::Coord(5, 6, 7)), 1.25f);
    EXPECT_EQ(grids.at("pressure")->getName(), "pressure");
    EXPECT_EQ(grids.at("pressure")->activeVoxelCount(), 1u);
    EXPECT_FLOAT_EQ(grids.at("density")->tree().getValue(openvdb::Coord(-4, 0, 7)), -0.75f);
}

// ---- atomic writes --------------------------------------------------------------------------

TEST_F(VdbIOTest, WriteIntoMissingDirectoryIsInputErrorAndLeavesNoFile)
{
    const fs::path missing = mDir / "no_such_dir";
    const std::string path = (missing / "out.vdb").string();
    const std::string msg = inputErrorOf([&] { writeVdbAtomic(path, {makeFloatGrid("density")}); });
    EXPECT_CONTAINS(msg, missing.string());
    EXPECT_CONTAINS(msg, "does not exist");
    EXPECT_FALSE(fs::exists(missing));
    EXPECT_TRUE(fs::is_empty(mDir));

    const std::string textMsg = inputErrorOf([&] { writeTextAtomic((missing / "out.json").string(), "{}"); });
    EXPECT_CONTAINS(textMsg, missing.string());
    EXPECT_TRUE(fs::is_empty(mDir));
}

TEST_F(VdbIOTest, WriteOverADirectoryIsInputError)
{
    fs::create_directory(mDir / "out.vdb");
    const std::string msg = inputErrorOf([&] { writeVdbAtomic(file("out.vdb"), {makeFloatGrid("density")}); });
    EXPECT_CONTAINS(msg, "is a directory");
    EXPECT_TRUE(tempFiles().empty());
}

TEST_F(VdbIOTest, SuccessfulWriteLeavesNoTempFileAndReplacesTheOldFile)
{
    const std::string path = file("out.vdb");
    writeVdbAtomic(path, {makeFloatGrid("old")});
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("licvdb test"));
    writeVdbAtomic(path, {makeFloatGrid("density"), makeVec3Grid("velocity")}, meta);
    EXPECT_TRUE(tempFiles().empty());
    EXPECT_EQ(std::distance(fs::directory_iterator(mDir), fs::directory_iterator()), 1);

    const auto d = describeVdb(path);
    ASSERT_EQ(d["grids"].size(), 2u);
    EXPECT_EQ(d["grids"][0]["name"], "density");
    EXPECT_EQ(d["grids"][1]["name"], "velocity");
    EXPECT_EQ(d["file_metadata"]["creator"], "licvdb test");
}

TEST_F(VdbIOTest, WrittenGridsHaveNoActiveTilesAndInputIsUntouched)
{
    auto filled = openvdb::FloatGrid::create(0.0f);
    filled->setName("density");
    filled->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(31)), 0.5f, /*active=*/true);
    auto tiled = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    tiled->setName("velocity");
    // A level-1 tile covers 8^3 voxels (one leaf's worth).
    tiled->tree().addTile(/*level=*/1, openvdb::Coord(128, 0, 0), openvdb::Vec3s(1.0f, 0.0f, 0.0f), true);
    ASSERT_GT(filled->tree().activeTileCount(), 0u);
    ASSERT_EQ(tiled->tree().activeTileCount(), 1u);
    const auto filledTiles = filled->tree().activeTileCount();

    const std::string path = file("tiles.vdb");
    writeVdbAtomic(path, {filled, tiled});
    EXPECT_EQ(filled->tree().activeTileCount(), filledTiles) << "the caller's grid was modified";

    const auto scalars = readScalarGrids(path);
    const auto& density = scalars.at("density");
    EXPECT_EQ(density->tree().activeTileCount(), 0u);
    EXPECT_EQ(density->activeVoxelCount(), 32u * 32u * 32u);
    EXPECT_EQ(density->tree().leafCount(), 64u);
    EXPECT_FLOAT_EQ(density->tree().getValue(openvdb::Coord(17, 3, 30)), 0.5f);

    auto velocity = readVelocityGrid(path);
    EXPECT_EQ(velocity->tree().activeTileCount(), 0u);
    EXPECT_EQ(velocity->activeVoxelCount(), 8u * 8u * 8u);
    EXPECT_EQ(velocity->tree().leafCount(), 1u);
    EXPECT_EQ(velocity->tree().getValue(openvdb::Coord(130, 5, 3)), openvdb::Vec3s(1.0f, 0.0f, 0.0f));
}

namespace {

std::string fileBytes(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// A grid of `leaves` leaves of noisy values (some voxels inactive, so the mask compression has
/// work), with `name`, stored as half or not.
template<typename GridT>
typename GridT::Ptr noisyGrid(const std::string& name, int leaves, bool half, unsigned seed)
{
    auto grid = GridT::create();
    grid->setName(name);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->setSaveFloatAsHalf(half);
    grid->insertMeta("lic_note", openvdb::StringMetadata(name + " metadata"));
    auto acc = grid->getAccessor();
    unsigned h = seed;
    for (int l = 0; l < leaves; ++l)
        for (int v = 0; v < 512; ++v) {
            h = h * 1664525u + 1013904223u;
            if ((h >> 28) == 0) continue; // ~1/16 stay inactive
            const openvdb::Coord ijk(8 * (l % 7) + (v >> 6), 8 * (l / 7) + ((v >> 3) & 7), (v & 7) - 20);
            acc.setValue(ijk, typename GridT::ValueType(float(h >> 8) / 16777216.0f));
        }
    return grid;
}

/// A float grid whose leaves cover each mask-compression kind the writer meets: inactive voxels
/// all background, one other inactive value, two (a selection mask), more than two (no mask
/// compression), and no inactive voxel at all.
openvdb::FloatGrid::Ptr inactiveKindsGrid(const std::string& name)
{
    auto grid = openvdb::FloatGrid::create(0.25f);
    grid->setName(name);
    auto acc = grid->getAccessor();
    for (int kind = 0; kind < 5; ++kind)
        for (int v = 0; v < 512; ++v) {
            const openvdb::Coord ijk(8 * kind + (v >> 6), (v >> 3) & 7, v & 7);
            const float value = float(v) / 512.0f;
            if (kind == 4 || v % 3 != 0) acc.setValueOn(ijk, value);
            else if (kind == 0) acc.setValueOff(ijk, 0.25f);
            else if (kind == 1) acc.setValueOff(ijk, 0.5f);
            else if (kind == 2) acc.setValueOff(ijk, v % 2 ? 0.5f : 0.75f);
            else acc.setValueOff(ijk, float(v % 5));
        }
    return grid;
}

} // namespace

// detail::writeVdbFile compresses each leaf once, on all cores, and writes the records itself;
// the file must be what io::File::write makes, byte for byte, but for the random UUID in the
// header, and read back. Both ways: the compressed leaves held in memory, and streamed (a hold
// of 0 bytes: every grid compressed twice and written chunk by chunk).
TEST_F(VdbIOTest, ParallelWriteGivesTheBytesOfOpenVdbsWriter)
{
    auto levelSet = noisyGrid<openvdb::FloatGrid>("distance", 3, false, 7);
    levelSet->setGridClass(openvdb::GRID_LEVEL_SET);
    auto halfVectors = noisyGrid<openvdb::Vec3SGrid>("tangent", 5, true, 8);
    auto doubles = noisyGrid<openvdb::DoubleGrid>("temperature", 4, false, 9); // OpenVDB's own path
    auto empty = openvdb::FloatGrid::create();
    empty->setName("empty");
    openvdb::GridCPtrVec grids{noisyGrid<openvdb::FloatGrid>("density", 150, false, 1),
                               noisyGrid<openvdb::FloatGrid>("halo", 25, true, 2),
                               noisyGrid<openvdb::Vec3SGrid>("velocity", 9, false, 3),
                               noisyGrid<openvdb::FloatGrid>("width", 1, false, 4),
                               inactiveKindsGrid("kinds"), levelSet, halfVectors, doubles, empty};
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("licvdb test"));
    for (const std::uint64_t hold : {vdbexport::detail::kWriteHoldBytes, std::uint64_t(0)})
        for (std::size_t n : {std::size_t(1), std::size_t(2), std::size_t(4), grids.size()}) {
            const openvdb::GridCPtrVec some(grids.begin(), grids.begin() + std::ptrdiff_t(n));
            const std::string what = std::to_string(n) + " grids, hold " + std::to_string(hold);
            const std::string ours = file("ours" + std::to_string(n) + ".vdb"), ref = file("ref" + std::to_string(n) + ".vdb");
            vdbexport::detail::writeVdbFile(ours, some, meta, hold);
            openvdb::io::File(ref).write(some, meta);
            const std::string a = fileBytes(ours), b = fileBytes(ref);
            ASSERT_EQ(a.size(), b.size()) << what;
            // The header: magic (8), file version (4), library version (8), offsets flag (1), then
            // the UUID as 36 characters.
            constexpr std::size_t kUuid = 21, kUuidEnd = 21 + 36;
            ASSERT_GT(a.size(), kUuidEnd);
            EXPECT_NE(a.substr(kUuid, 36), b.substr(kUuid, 36)) << "two writes gave the same random UUID";
            EXPECT_EQ(a.substr(0, kUuid), b.substr(0, kUuid)) << what;
            EXPECT_TRUE(a.substr(kUuidEnd) == b.substr(kUuidEnd)) << what << ": the files differ after the header";

            openvdb::io::File in(ours);
            in.open(/*delayLoad=*/false);
            const auto back = in.getGrids(); // (in name order)
            ASSERT_EQ(back->size(), n);
            for (std::size_t i = 0; i < n; ++i) {
                const auto g = std::find_if(back->begin(), back->end(),
                                            [&](const auto& read) { return read->getName() == some[i]->getName(); });
                ASSERT_NE(g, back->end()) << what << ": " << some[i]->getName();
                EXPECT_EQ((*g)->activeVoxelCount(), some[i]->activeVoxelCount()) << what;
            }
            in.close();
            // Random access by name uses the descriptors' stream positions, and a delayed load
            // the table of compressed sizes: every float grid's values must come back.
            openvdb::io::File lazy(ours);
            lazy.open(/*delayLoad=*/true);
            for (std::size_t i = 0; i < n; ++i) {
                const auto src = openvdb::gridConstPtrCast<openvdb::FloatGrid>(some[i]);
                if (!src) continue;
                const auto got = openvdb::gridPtrCast<openvdb::FloatGrid>(lazy.readGrid(src->getName()));
                ASSERT_TRUE(got) << what << ": " << src->getName();
                for (auto it = src->cbeginValueAll(); it; ++it) {
                    if (!it.isVoxelValue()) continue;
                    const float want = src->saveFloatAsHalf() ? float(openvdb::math::half(*it)) : *it;
                    ASSERT_EQ(got->tree().getValue(it.getCoord()), want) << what << ": " << src->getName();
                }
            }
            lazy.close();
        }
}

// Sealed leaves (vdbexport/io/SealedLeaves.h): each leaf's record made ahead, the grid holding
// topology-only leaves. The writer must give the file whole leaves give, byte for byte but for the
// UUID, and refuse records made for another precision or a grid that mixes both kinds of leaf.
TEST_F(VdbIOTest, SealedLeavesAreWrittenAsTheWholeLeavesWouldBe)
{
    auto density = noisyGrid<openvdb::FloatGrid>("density", 40, true, 11);
    auto velocity = noisyGrid<openvdb::Vec3SGrid>("velocity", 12, true, 12);
    velocity->setGridClass(openvdb::GRID_UNKNOWN);
    const openvdb::GridCPtrVec whole{density, velocity};
    vdbexport::detail::SealedLeaves sealer(/*half=*/true);
    sealer.begin({"density", "velocity"}, 1);
    auto sealGrid = [&](const auto& grid, int index, bool keepOneWhole) {
        using GridT = typename std::decay_t<decltype(*grid)>;
        auto out = openvdb::gridPtrCast<GridT>(grid->copyGridWithNewTree());
        bool first = true;
        for (auto it = grid->constTree().cbeginLeaf(); it; ++it) {
            const std::uint32_t tag = sealer.seal(index, *it, 0);
            if (keepOneWhole && std::exchange(first, false)) out->tree().addLeaf(new typename GridT::TreeType::LeafNodeType(*it));
            else out->tree().addLeaf(lic::topologyOnly(*it, tag).release());
        }
        return out;
    };
    const auto sealedDensity = sealGrid(density, 0, false);
    const auto sealedVelocity = sealGrid(velocity, 1, false);
    for (auto it = sealedDensity->constTree().cbeginLeaf(); it; ++it) ASSERT_FALSE(it->isAllocated());
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("licvdb test"));
    const std::string ref = file("whole.vdb"), ours = file("sealed.vdb");
    vdbexport::detail::writeVdbFile(ref, whole, meta);
    vdbexport::detail::writeVdbFile(ours, {sealedDensity, sealedVelocity}, meta, vdbexport::detail::kWriteHoldBytes, &sealer);
    const std::string a = fileBytes(ours), b = fileBytes(ref);
    constexpr std::size_t kUuid = 21, kUuidEnd = 21 + 36;
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(a.substr(0, kUuid), b.substr(0, kUuid));
    EXPECT_TRUE(a.substr(kUuidEnd) == b.substr(kUuidEnd)) << "sealed and whole leaves give different files";
    // Writing read nothing but masks: no leaf got a buffer (OpenVDB 13's bounding box would give each one).
    for (auto it = sealedDensity->constTree().cbeginLeaf(); it; ++it) ASSERT_FALSE(it->isAllocated()) << "after writing";

    // Records made for half floats, the grid now saved as float: refused, naming the grid.
    sealedDensity->setSaveFloatAsHalf(false);
    try {
        vdbexport::detail::writeVdbFile(file("mismatch.vdb"), {sealedDensity}, meta, vdbexport::detail::kWriteHoldBytes, &sealer);
        ADD_FAILURE() << "records made for half floats were written as floats";
    } catch (const lic::Error& e) {
        EXPECT_NE(std::string(e.what()).find("'density'"), std::string::npos) << e.what();
    }
    // One whole leaf among sealed ones: refused.
    const auto mixed = sealGrid(velocity, 1, true);
    EXPECT_THROW(vdbexport::detail::writeVdbFile(file("mixed.vdb"), {mixed}, meta, vdbexport::detail::kWriteHoldBytes, &sealer),
                 lic::Error);
}

// A loop's sealed records go to a spool file in the output directory, each thread gathering a
// grid's records and writing them when its buffer fills (or at flush()). Sealed on several
// threads, grids interleaved leaf by leaf as a brick seals them, with enough leaves that the
// buffers fill and spill many times: the file must be whole leaves' byte for byte, and reading
// the records before flush() is a programming error, not a file with holes.
TEST_F(VdbIOTest, SpooledSealedLeavesAreWrittenAsTheWholeLeavesWouldBe)
{
    auto density = noisyGrid<openvdb::FloatGrid>("density", 2000, false, 21);
    auto halo = noisyGrid<openvdb::FloatGrid>("halo", 2000, false, 22);
    vdbexport::detail::SealedLeaves sealer(/*half=*/false, mDir.string());
    sealer.begin({"density", "halo"}, 2);
    std::vector<const openvdb::FloatTree::LeafNodeType*> a, b;
    for (auto it = density->constTree().cbeginLeaf(); it; ++it) a.push_back(it.getLeaf());
    for (auto it = halo->constTree().cbeginLeaf(); it; ++it) b.push_back(it.getLeaf());
    ASSERT_EQ(a.size(), b.size());
    std::vector<std::uint32_t> tagA(a.size()), tagB(b.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, a.size(), 8), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            tagA[i] = sealer.seal(0, *a[i], int(i % 2));
            tagB[i] = sealer.seal(1, *b[i], int(i % 2));
        }
    });
    auto topology = [](const openvdb::FloatGrid& grid, const auto& leaves, const std::vector<std::uint32_t>& tags) {
        auto out = openvdb::gridPtrCast<openvdb::FloatGrid>(grid.copyGridWithNewTree());
        for (std::size_t i = 0; i < leaves.size(); ++i) out->tree().addLeaf(lic::topologyOnly(*leaves[i], tags[i]).release());
        return out;
    };
    const auto sealedDensity = topology(*density, a, tagA), sealedHalo = topology(*halo, b, tagB);
    const std::string ref = file("whole.vdb"), ours = file("spooled.vdb");
    EXPECT_THROW(vdbexport::detail::writeVdbFile(ours, {sealedDensity, sealedHalo}, {}, vdbexport::detail::kWriteHoldBytes,
                                                 &sealer),
                 std::logic_error);
    sealer.flush();
    vdbexport::detail::writeVdbFile(ref, {density, halo}, {});
    vdbexport::detail::writeVdbFile(ours, {sealedDensity, sealedHalo}, {}, vdbexport::detail::kWriteHoldBytes, &sealer);
    const std::string x = fileBytes(ours), y = fileBytes(ref);
    constexpr std::size_t kUuid = 21, kUuidEnd = 21 + 36;
    ASSERT_EQ(x.size(), y.size());
    EXPECT_GT(x.size(), std::size_t(6) << 20) << "too few leaves to fill the spool's buffers";
    EXPECT_EQ(x.substr(0, kUuid), y.substr(0, kUuid));
    EXPECT_TRUE(x.substr(kUuidEnd) == y.substr(kUuidEnd)) << "spooled and whole leaves give different files";
}

// Names Archive would change (a repeated name) take io::File::write's path: still a readable
// file with both grids.
TEST_F(VdbIOTest, ParallelWriteFallsBackForRepeatedNames)
{
    openvdb::GridCPtrVec grids{noisyGrid<openvdb::FloatGrid>("density", 3, false, 1),
                               noisyGrid<openvdb::FloatGrid>("density", 2, false, 2)};
    const std::string ours = file("ours.vdb"), ref = file("ref.vdb");
    vdbexport::detail::writeVdbFile(ours, grids, {});
    openvdb::io::File(ref).write(grids, {});
    const std::string a = fileBytes(ours), b = fileBytes(ref);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_TRUE(a.substr(57) == b.substr(57));
}

TEST_F(VdbIOTest, WriteTextAtomicWritesAndReplaces)
{
    const std::string path = file("out.json");
    writeTextAtomic(path, "first");
    writeTextAtomic(path, "{\"grids\": [\"density\"]}\n");
    EXPECT_EQ(readFile(path), "{\"grids\": [\"density\"]}\n");
    EXPECT_TRUE(tempFiles().empty());
}

// ---- describeVdb / formatInfo ---------------------------------------------------------------

namespace {

/// density: float, 3 voxels, voxel size 0.5 translated by (1,-2,3), with one metadata value of
/// each type; velocity: the 4×3×2 vec3s grid of makeVec3Grid.
std::string writeDescribedFile(const std::string& path)
{
    auto density = openvdb::FloatGrid::create(0.0f);
    density->setName("density");
    density->setGridClass(openvdb::GRID_FOG_VOLUME);
    density->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    density->transform().postTranslate(openvdb::Vec3d(1.0, -2.0, 3.0));
    auto acc = density->getAccessor();
    acc.setValue(openvdb::Coord(0, 0, 0), 0.25f);
    acc.setValue(openvdb::Coord(3, 1, 2), 1.0f);
    acc.setValue(openvdb::Coord(-2, 5, 0), 0.1f);
    density->insertMeta("lic_engine", openvdb::StringMetadata("fast"));
    density->insertMeta("lic_frames", openvdb::Int32Metadata(24));
    density->insertMeta("lic_count", openvdb::Int64Metadata(int64_t(1) << 40));
    density->insertMeta("lic_step", openvdb::FloatMetadata(0.1f));
    density->insertMeta("lic_length", openvdb::DoubleMetadata(20.5));
    density->insertMeta("lic_cyclic", openvdb::BoolMetadata(true));
    density->insertMeta("light_dir", openvdb::Vec3SMetadata(openvdb::Vec3s(0.5f, -1.0f, 2.0f)));
    density->insertMeta("res", openvdb::Vec3IMetadata(openvdb::Vec3i(64, 32, 16)));
    density->insertMeta("not_json", openvdb::StringMetadata("{not json"));
    std::string recipe = R"({"field": {"path": "jet.vdb", "grid": "velocity"}, "lic": {"engine": "fast", "length": 20}, "notes": ")";
    recipe += std::string(200, 'x') + "\"}";
    density->insertMeta("licvdb_recipe", openvdb::StringMetadata(recipe));

    openvdb::MetaMap fileMeta;
    fileMeta.insertMeta("creator", openvdb::StringMetadata("licvdb"));
    fileMeta.insertMeta("frame", openvdb::Int32Metadata(3));
    writeVdbAtomic(path, {density, makeVec3Grid("velocity")}, fileMeta);
    return path;
}

} // namespace

TEST_F(VdbIOTest, DescribeReportsGridsBoundsAndMetadata)
{
    const std::string path = writeDescribedFile(file("described.vdb"));
    const nlohmann::json d = describeVdb(path);
    EXPECT_EQ(d["path"], path);
    EXPECT_EQ(d["file_metadata"]["creator"], "licvdb");
    EXPECT_EQ(d["file_metadata"]["frame"], 3);
    ASSERT_EQ(d["grids"].size(), 2u);

    const auto& g = d["grids"][0];
    EXPECT_EQ(g["name"], "density");
    EXPECT_EQ(g["value_type"], "float");
    EXPECT_EQ(g["class"], "fog volume");
    EXPECT_EQ(g["active_voxels"], 3);
    EXPECT_EQ(g["active_tiles"], 0);
    EXPECT_EQ(g["leaf_nodes"], 2); // (-2,5,0) is in a different leaf from (0..3, 0..1, 0..2)
    EXPECT_EQ(g["index_bbox"], nlohmann::json::parse("[[-2,0,0],[3,5,2]]"));
    // world = 0.5 * index + (1,-2,3), over index min-0.5 .. max+0.5
    const auto& wb = g["world_bbox"];
    const double expectMin[3] = {0.5 * -2.5 + 1.0, 0.5 * -0.5 - 2.0, 0.5 * -0.5 + 3.0};
    const double expectMax[3] = {0.5 * 3.5 + 1.0, 0.5 * 5.5 - 2.0, 0.5 * 2.5 + 3.0};
    for (int c = 0; c < 3; ++c) {
        EXPECT_DOUBLE_EQ(wb[0][c].get<double>(), expectMin[c]) << "component " << c;
        EXPECT_DOUBLE_EQ(wb[1][c].get<double>(), expectMax[c]) << "component " << c;
        EXPECT_DOUBLE_EQ(g["voxel_size"][c].get<double>(), 0.5);
    }
    EXPECT_GT(g["memory_bytes"].get<uint64_t>(), 0u);
    EXPECT_EQ(g["value_range"], nlohmann::json::parse("[0.1, 1.0]"));
    EXPECT_EQ(g["non_finite_values"], 0);

    const auto& m = g["metadata"];
    EXPECT_EQ(m["lic_engine"], "fast");
    EXPECT_EQ(m["lic_frames"], 24);
    EXPECT_EQ(m["lic_count"], int64_t(1) << 40);
    EXPECT_EQ(m["lic_step"], 0.1); // a float shown by its shortest form, not 0.10000000149…
    EXPECT_EQ(m["lic_length"], 20.5);
    EXPECT_EQ(m["lic_cyclic"], true);
    EXPECT_EQ(m["light_dir"], nlohmann::json::parse("[0.5, -1.0, 2.0]"));
    EXPECT_EQ(m["res"], nlohmann::json::parse("[64, 32, 16]"));
    EXPECT_EQ(m["not_json"], "{not json");
    ASSERT_TRUE(m["licvdb_recipe"].is_object()) << m["licvdb_recipe"];
    EXPECT_EQ(m["licvdb_recipe"]["field"]["grid"], "velocity");
    EXPECT_EQ(m["licvdb_recipe"]["lic"]["length"], 20);
    EXPECT_FALSE(m.contains("name"));
    EXPECT_FALSE(m.contains("class"));
    EXPECT_FALSE(m.contains("file_voxel_count"));

    const auto& v = d["grids"][1];
    EXPECT_EQ(v["name"], "velocity");
    EXPECT_EQ(v["value_type"], "vec3s");
    EXPECT_EQ(v["class"], "staggered");
    EXPECT_EQ(v["active_voxels"], 24);
    EXPECT_EQ(v["index_bbox"], nlohmann::json::parse("[[0,0,0],[3,2,1]]"));
    // |v| over i in 0..3, j in 0..2, k in 0..1 with v = (i+0.25, j-1.5, k+0.125)
    ASSERT_TRUE(v["value_range"].is_array());
    EXPECT_NEAR(v["value_range"][0].get<double>(), std::sqrt(0.25 * 0.25 + 0.5 * 0.5 + 0.125 * 0.125), 1e-6);
    EXPECT_NEAR(v["value_range"][1].get<double>(), std::sqrt(3.25 * 3.25 + 1.5 * 1.5 + 1.125 * 1.125), 1e-6);
}

TEST_F(VdbIOTest, DescribeCountsTilesAndNonFiniteValues)
{
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("tiled");
    grid->tree().addTile(/*level=*/1, openvdb::Coord(0), 2.0f, true); // 8^3 voxels
    grid->getAccessor().setValue(openvdb::Coord(-1, -1, -1), std::numeric_limits<float>::quiet_NaN());
    // Write with plain OpenVDB: writeVdbAtomic would voxelize the tile.
    const std::string path = file("tiled.vdb");
    openvdb::io::File(path).write({grid});

    const auto g = describeVdb(path)["grids"][0];
    EXPECT_EQ(g["active_tiles"], 1);
    EXPECT_EQ(g["active_voxels"], 8 * 8 * 8 + 1);
    EXPECT_EQ(g["leaf_nodes"], 1);
    EXPECT_EQ(g["index_bbox"], nlohmann::json::parse("[[-1,-1,-1],[7,7,7]]"));
    EXPECT_EQ(g["value_range"], nlohmann::json::parse("[2.0, 2.0]"));
    EXPECT_EQ(g["non_finite_values"], 1);
}

TEST_F(VdbIOTest, FormatInfoShowsEveryGridAndTruncatesLongMetadata)
{
    const std::string path = writeDescribedFile(file("described.vdb"));
    const std::string text = formatInfo(describeVdb(path));
    EXPECT_CONTAINS(text, path);
    EXPECT_CONTAINS(text, "density");
    EXPECT_CONTAINS(text, "velocity");
    EXPECT_CONTAINS(text, "fog volume");
    EXPECT_CONTAINS(text, "vec3s");
    EXPECT_CONTAINS(text, "lic_engine");
    EXPECT_CONTAINS(text, "creator");
    EXPECT_CONTAINS(text, "\"engine\":\"fast\""); // compact JSON on one line
    EXPECT_CONTAINS(text, "…");
    for (std::size_t start = 0; start < text.size();) {
        const std::size_t end = std::min(text.find('\n', start), text.size());
        EXPECT_LT(end - start, 160u) << "line too long: " << text.substr(start, end - start);
        start = end + 1;
    }
}

TEST_F(VdbIOTest, FormatInfoOfFileWithoutGrids)
{
    const std::string path = file("nogrids.vdb");
    writeVdbAtomic(path, {});
    const auto d = describeVdb(path);
    EXPECT_TRUE(d["grids"].empty());
    EXPECT_CONTAINS(formatInfo(d), "no grids");
    EXPECT_CONTAINS(inputErrorOf([&] { readVelocityGrid(path); }), "no Vec3 grid");
}

namespace {

/// Every value and active state of `a` and `b` (grids of type GridT) are the same, tiles included.
template<typename GridT>
void expectSameValues(const openvdb::GridBase& a, const openvdb::GridBase& b, const std::string& what)
{
    const auto& ta = static_cast<const GridT&>(a).tree();
    const auto& tb = static_cast<const GridT&>(b).tree();
    EXPECT_TRUE(ta.hasSameTopology(tb)) << what;
    EXPECT_EQ(ta.background(), tb.background()) << what;
    EXPECT_EQ(ta.leafCount(), tb.leafCount()) << what;
    std::size_t n = 0;
    for (auto it = ta.cbeginValueAll(); it; ++it, ++n) {
        typename GridT::ValueType v;
        const bool on = tb.probeValue(it.getCoord(), v);
        ASSERT_EQ(on, it.isValueOn()) << what << " at " << it.getCoord();
        ASSERT_EQ(v, *it) << what << " at " << it.getCoord();
    }
    EXPECT_GT(n, 0u) << what;
}

/// What io::File reads and what GridFileReader reads are the same grid: type, name, class,
/// half-float flag, metadata, transform, and every value.
void expectSameGrid(const openvdb::GridBase::Ptr& want, const openvdb::GridBase::Ptr& got, const std::string& what)
{
    ASSERT_TRUE(want) << what;
    ASSERT_TRUE(got) << what;
    ASSERT_EQ(got->type(), want->type()) << what;
    EXPECT_EQ(got->getName(), want->getName()) << what;
    EXPECT_EQ(got->getGridClass(), want->getGridClass()) << what;
    EXPECT_EQ(got->saveFloatAsHalf(), want->saveFloatAsHalf()) << what;
    EXPECT_EQ(static_cast<const openvdb::MetaMap&>(*got).str(), static_cast<const openvdb::MetaMap&>(*want).str()) << what;
    EXPECT_TRUE(got->constTransform() == want->constTransform()) << what;
    if (want->isType<openvdb::FloatGrid>()) expectSameValues<openvdb::FloatGrid>(*want, *got, what);
    else if (want->isType<openvdb::Vec3SGrid>()) expectSameValues<openvdb::Vec3SGrid>(*want, *got, what);
    else if (want->isType<openvdb::DoubleGrid>()) expectSameValues<openvdb::DoubleGrid>(*want, *got, what);
    else ADD_FAILURE() << what << ": a grid type this test does not compare: " << want->type();
}

} // namespace

// VdbReader reads grids through GridFileReader (a stream over pread, not io::File's ifstream):
// what it reads must be what io::File reads, grid by grid and all at once, for every kind of grid
// a file holds (half floats, vectors, doubles, a level set, tiles, repeated names, an instance).
TEST_F(VdbIOTest, GridReaderReadsWhatOpenVdbsFileReads)
{
    auto tiles = noisyGrid<openvdb::FloatGrid>("tiles", 3, false, 5);
    tiles->tree().addTile(2, openvdb::Coord(4096, 0, 0), 2.5f, true); // an active 128³ tile
    tiles->tree().addTile(1, openvdb::Coord(0, 4096, 0), 0.5f, false);
    auto levelSet = noisyGrid<openvdb::FloatGrid>("distance", 3, false, 7);
    levelSet->setGridClass(openvdb::GRID_LEVEL_SET);
    auto instance = noisyGrid<openvdb::FloatGrid>("shared", 1, false, 6);
    instance->setTree(tiles->treePtr()); // written as an instance of "tiles"
    instance->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
    auto big = noisyGrid<openvdb::Vec3SGrid>("velocity", 400, false, 3); // > 1 MiB: reads past the window
    const openvdb::GridCPtrVec grids{noisyGrid<openvdb::FloatGrid>("density", 30, false, 1),
                                     noisyGrid<openvdb::FloatGrid>("density", 12, true, 2), // "density[1]"
                                     big, tiles, instance, levelSet,
                                     noisyGrid<openvdb::Vec3SGrid>("tangent", 5, true, 8),
                                     noisyGrid<openvdb::DoubleGrid>("temperature", 4, false, 9)};
    const std::string path = file("many.vdb");
    openvdb::io::File(path).write(grids);

    openvdb::io::File ref(path);
    ref.open(/*delayLoad=*/false);
    vdbexport::detail::GridFileReader ours(path);
    ASSERT_TRUE(ours.random());
    for (const std::string name : {"density", "density[0]", "density[1]", "velocity", "tiles", "shared",
                                   "distance", "tangent", "temperature"})
        expectSameGrid(ref.readGrid(name), ours.readGrid(name), name);
    EXPECT_THROW(ours.readGrid("missing"), openvdb::KeyError);
    EXPECT_THROW(ours.readGrid("density[5]"), openvdb::KeyError);

    const auto want = ref.getGrids();
    const openvdb::GridPtrVec got = ours.readAllGrids();
    ASSERT_EQ(got.size(), want->size());
    for (std::size_t i = 0; i < got.size(); ++i) expectSameGrid((*want)[i], got[i], "all grids, #" + std::to_string(i));
    const auto byName = [](const openvdb::GridPtrVec& v, const std::string& n) {
        return *std::find_if(v.begin(), v.end(), [&](const auto& g) { return g->getName() == n; });
    };
    EXPECT_EQ(&byName(got, "shared")->baseTree(), &byName(got, "tiles")->baseTree()) << "the instance shares its parent's tree";
    ref.close();

    // Through VdbReader (after the structural check), as every read path takes it.
    vdbexport::detail::VdbReader reader(path);
    expectSameGrid(byName(*want, "velocity"), reader.readGrid("velocity"), "VdbReader velocity");
    EXPECT_EQ(reader.readAllGrids().size(), want->size());

    const std::string text = file("not.vdb");
    std::ofstream(text) << "plainly not a VDB file, but long enough to hold a header's bytes";
    EXPECT_THROW(vdbexport::detail::GridFileReader{text}, openvdb::IoError);
}

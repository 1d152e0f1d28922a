// Split velocity grids (Houdini's and EmberGen's `vel.x`, `vel.y`, `vel.z` float grids): a bake of
// the split field is bit-identical to the bake of the same field stored as one vec3 grid, with
// `--grid vel` and with the default grid choice (also `velocity.*`, `v.*`); components of
// different voxel sizes are refused; a missing component is named.
#include "TempDirSuite.h"

#include "vdbexport/bake/Bake.h"
#include "vdbexport/io/FieldInput.h"
#include "vdbexport/io/AtomicWrite.h"

#include "lic/util/Error.h"

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>


namespace fs = std::filesystem;
using openvdb::Vec3s;

namespace {

/// A sheared, swirling flow (world units per second) at index (i, j, k) of a 16³ box.
Vec3s flowAt(int i, int j, int k)
{
    return Vec3s(1.0f + 0.05f * float(j), 0.4f * std::sin(0.3f * float(k)), 0.02f * float(i) - 0.1f);
}

openvdb::math::Transform::Ptr fieldTransform(double voxel = 0.1)
{
    auto xf = openvdb::math::Transform::createLinearTransform(voxel);
    xf->postTranslate(openvdb::Vec3d(-0.8, 0.25, 1.0));
    return xf;
}

/// Component `a` of the flow as float grid `name` (every voxel of the 16³ box active).
openvdb::FloatGrid::Ptr componentGrid(const std::string& name, int a, openvdb::math::Transform::Ptr xf)
{
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setName(name);
    g->setTransform(xf);
    for (int i = 0; i < 16; ++i)
        for (int j = 0; j < 16; ++j)
            for (int k = 0; k < 16; ++k) g->tree().setValueOn(openvdb::Coord(i, j, k), flowAt(i, j, k)[a]);
    return g;
}

openvdb::Vec3SGrid::Ptr vectorGrid(const std::string& name)
{
    auto g = openvdb::Vec3SGrid::create(Vec3s(0.0f));
    g->setName(name);
    g->setTransform(fieldTransform());
    g->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    for (int i = 0; i < 16; ++i)
        for (int j = 0; j < 16; ++j)
            for (int k = 0; k < 16; ++k) g->tree().setValueOn(openvdb::Coord(i, j, k), flowAt(i, j, k));
    return g;
}

/// The three components named `base` + ".x" … (those of `axes`), with the field's transform.
openvdb::GridPtrVec splitGrids(const std::string& base, const std::string& axes = "xyz")
{
    openvdb::GridPtrVec grids;
    for (const char a : axes) grids.push_back(componentGrid(base + "." + a, a - 'x', fieldTransform()));
    return grids;
}

openvdb::FloatGrid::Ptr readDensity(const std::string& path)
{
    openvdb::io::File file(path);
    file.open(false);
    auto g = openvdb::GridBase::grid<openvdb::FloatGrid>(file.readGrid("density"));
    file.close();
    return g;
}

void expectInputError(const std::function<void()>& fn, const std::vector<std::string>& words)
{
    try {
        fn();
        ADD_FAILURE() << "no exception";
    } catch (const lic::InputError& e) {
        const std::string msg = e.what();
        for (const auto& w : words) EXPECT_NE(msg.find(w), std::string::npos) << "message lacks '" << w << "': " << msg;
    }
}

class SplitVelocity : public lictest::TempDirTest
{
protected:
    std::string path(const std::string& name) const { return (mDir / name).string(); }

    /// A short noise bake of `field` (grid `grid`, "" = the default choice) into `out`.
    openvdb::FloatGrid::Ptr bake(const std::string& field, const std::string& grid, const std::string& out)
    {
        vdbexport::Recipe r;
        r.field.path = path(field);
        r.field.grid = grid;
        r.output.path = path(out);
        r.lic.length = 6;
        r.threads = 2;
        const auto summary = vdbexport::bake(r);
        EXPECT_EQ(summary["field"]["grid"], grid.empty() ? "vel" : grid);
        return readDensity(r.output.path);
    }
};

void expectBitIdentical(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b, const std::string& what)
{
    EXPECT_TRUE(a.tree().hasSameTopology(b.tree())) << what;
    auto acc = b.getConstAccessor();
    std::size_t differ = 0;
    for (auto it = a.cbeginValueOn(); it; ++it) {
        const float va = *it, vb = acc.getValue(it.getCoord());
        differ += std::memcmp(&va, &vb, sizeof(float)) != 0;
    }
    EXPECT_EQ(differ, 0u) << what << ": " << differ << " of " << a.activeVoxelCount();
    EXPECT_GT(a.activeVoxelCount(), 1000u) << what;
}

TEST_F(SplitVelocity, BakesBitIdenticalToOneVec3Grid)
{
    vdbexport::writeVdbAtomic(path("vec.vdb"), {vectorGrid("vel")});
    openvdb::GridPtrVec split = splitGrids("vel");
    auto density = openvdb::FloatGrid::create(0.0f);
    density->setName("density");
    density->setTransform(fieldTransform());
    density->tree().setValueOn(openvdb::Coord(3), 1.0f);
    split.push_back(density); // another float grid beside the components changes nothing
    vdbexport::writeVdbAtomic(path("split.vdb"), split);
    vdbexport::FieldSpec vs, ss;
    vs.path = path("vec.vdb");
    ss.path = path("split.vdb");
    const vdbexport::LoadedField fv = vdbexport::loadField(vs), fs = vdbexport::loadField(ss);
    EXPECT_EQ(fv.velocity->transform(), fs.velocity->transform());
    EXPECT_TRUE(fv.velocity->tree().hasSameTopology(fs.velocity->tree()));
    std::size_t differ = 0;
    for (auto it = fv.velocity->cbeginValueOn(); it; ++it) differ += *it != fs.velocity->tree().getValue(it.getCoord());
    EXPECT_EQ(differ, 0u);
    const auto reference = bake("vec.vdb", "vel", "a.vdb");
    expectBitIdentical(*reference, *bake("split.vdb", "vel", "b.vdb"), "--grid vel: split vs vec3");
    expectBitIdentical(*reference, *bake("split.vdb", "", "c.vdb"), "default grid: split vs vec3");
}

TEST_F(SplitVelocity, DefaultChoiceFindsVelocityAndVComponents)
{
    for (const std::string base : {"velocity", "v"}) {
        vdbexport::writeVdbAtomic(path(base + ".vdb"), splitGrids(base));
        vdbexport::FieldSpec spec;
        spec.path = path(base + ".vdb");
        const vdbexport::LoadedField f = vdbexport::loadField(spec);
        EXPECT_EQ(f.gridName, base);
        EXPECT_EQ(f.velocity->activeVoxelCount(), 16u * 16u * 16u);
        EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(5, 7, 9)), flowAt(5, 7, 9));
    }
}

TEST_F(SplitVelocity, DifferentVoxelSizesAreRefusedHalfVoxelOffsetsSampled)
{
    openvdb::GridPtrVec grids = splitGrids("vel");
    grids[1] = componentGrid("vel.y", 1, fieldTransform(0.2));
    vdbexport::writeVdbAtomic(path("mixed.vdb"), grids);
    vdbexport::FieldSpec spec;
    spec.path = path("mixed.vdb");
    expectInputError([&] { vdbexport::loadField(spec); },
                     {"mixed.vdb", "different transforms", "'vel.y' voxel size [0.2, 0.2, 0.2]", "'vel.x' voxel size [0.1"});
    // A face-centred layout (the y component half a voxel along y) shares the voxel size: read.
    auto mac = fieldTransform();
    mac->postTranslate(openvdb::Vec3d(0.0, 0.05, 0.0));
    grids[1] = componentGrid("vel.y", 1, mac);
    vdbexport::writeVdbAtomic(path("mac.vdb"), grids);
    spec.path = path("mac.vdb");
    EXPECT_EQ(vdbexport::loadField(spec).gridName, "vel");
}

TEST_F(SplitVelocity, AMissingComponentIsNamed)
{
    vdbexport::writeVdbAtomic(path("xy.vdb"), splitGrids("vel", "xy"));
    vdbexport::FieldSpec spec;
    spec.path = path("xy.vdb");
    spec.grid = "vel";
    expectInputError([&] { vdbexport::loadField(spec); },
                     {"xy.vdb", "'vel.x', 'vel.y' found", "'vel.z' missing", "the file has", "vel.x", "float"});
    spec.grid = "";
    expectInputError([&] { vdbexport::loadField(spec); }, {"xy.vdb", "no Vec3 grid", "'vel.z' missing", "the file has"});
}

} // namespace

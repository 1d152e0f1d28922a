// The sample .vdb files of VdbSamples.h. One translation unit: writing every value type OpenVDB
// registers instantiates its grids, trees and I/O, which took ~110 s (release) and ~200 s (ASan)
// of each test file that included it (docs/performance.md, "CI time").
#include "VdbSamples.h"

#include <lic/field/Presets.h>

#include "vdbexport/io/AtomicWrite.h"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <fstream>

namespace vdb_samples {

namespace fs = std::filesystem;

namespace {

/// A smoke-like float grid: a ball of density with smooth values, `res`³ voxels.
openvdb::FloatGrid::Ptr smoke(const std::string& name, int res, double voxelSize)
{
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setName(name);
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setTransform(openvdb::math::Transform::createLinearTransform(voxelSize));
    auto acc = g->getAccessor();
    const double c = 0.5 * res;
    for (int i = 0; i < res; ++i)
        for (int j = 0; j < res; ++j)
            for (int k = 0; k < res; ++k) {
                const double r = std::sqrt((i - c) * (i - c) + (j - c) * (j - c) + (k - c) * (k - c));
                if (r < 0.45 * res) acc.setValue(openvdb::Coord(i, j, k), float(1.0 - r / (0.45 * res)));
            }
    return g;
}

/// `grids` written with plain OpenVDB (tiles stay tiles) and the given compression flags.
void writePlain(const fs::path& path, const openvdb::GridPtrVec& grids, uint32_t compression,
                const openvdb::MetaMap& meta = {})
{
    openvdb::io::File file(path.string());
    file.setCompression(compression);
    file.write(grids, meta);
    file.close();
}

} // namespace

std::vector<std::string> writeVdbSamples(const std::filesystem::path& dir, int res)
{
    openvdb::initialize();
    using namespace openvdb;
    std::vector<std::string> out;
    const auto add = [&](const std::string& name) {
        out.push_back((dir / name).string());
        return dir / name;
    };

    // 1. What `licvdb field abc` writes (writeVdbAtomic: blosc + active mask).
    {
        const lic::PresetField f = lic::makePresetField("abc", Coord(res));
        GridPtrVec grids{f.velocity};
        for (const auto& s : f.scalars) grids.push_back(s);
        vdbexport::writeVdbAtomic(add("field_abc_blosc.vdb").string(), grids);
    }
    // 2./3. A Blender mantaflow cache: staggered velocity and fog grids stored as half floats,
    // blosc (Blender's default) and zip (fog volumes are never zipped: their values stay raw).
    for (const uint32_t compression : {io::COMPRESS_BLOSC | io::COMPRESS_ACTIVE_MASK,
                                       io::COMPRESS_ZIP | io::COMPRESS_ACTIVE_MASK}) {
        const lic::PresetField f = lic::makePresetField("tabbed-jet", Coord(res));
        auto vel = f.velocity->deepCopy();
        vel->setName("velocity");
        vel->setGridClass(GRID_STAGGERED);
        vel->setTransform(math::Transform::createLinearTransform(0.125));
        auto density = smoke("density", res, 0.125);
        auto flame = smoke("flame", res / 2, 0.125);
        GridPtrVec grids{density, flame, vel};
        for (auto& g : grids) g->setSaveFloatAsHalf(true);
        MetaMap meta;
        meta.insertMeta("creator", StringMetadata("Blender/Mantaflow (licvdb test sample)"));
        writePlain(add(compression & io::COMPRESS_ZIP ? "mantaflow_half_zip.vdb" : "mantaflow_half_blosc.vdb"), grids,
                   compression, meta);
    }
    // 4. Houdini-style split velocity: vel.x, vel.y, vel.z float grids, zip.
    {
        const lic::PresetField f = lic::makePresetField("abc", Coord(res));
        GridPtrVec grids;
        for (int a = 0; a < 3; ++a) {
            auto g = FloatGrid::create(0.0f);
            g->setName(std::string("vel.") + "xyz"[a]);
            g->setTransform(f.velocity->transform().copy());
            for (auto it = f.velocity->cbeginValueOn(); it; ++it) g->tree().setValue(it.getCoord(), (*it)[a]);
            grids.push_back(g);
        }
        writePlain(add("houdini_split_zip.vdb"), grids, io::COMPRESS_ZIP | io::COMPRESS_ACTIVE_MASK);
    }
    // 5. A licvdb-style bake: density and halo (half), color, recipe metadata, blosc.
    {
        auto density = smoke("density", res, 0.25);
        density->insertMeta("licvdb_recipe", StringMetadata("{\"lic\": {\"engine\": \"fast\", \"length\": 4}}"));
        density->insertMeta("lic_frames", Int32Metadata(1));
        density->insertMeta("lic_cyclic", BoolMetadata(false));
        density->insertMeta("lic_length", FloatMetadata(4.0f));
        density->setSaveFloatAsHalf(true);
        auto halo = smoke("halo", res, 0.25);
        halo->setSaveFloatAsHalf(true);
        auto color = Vec3SGrid::create(Vec3s(0.0f));
        color->setName("color");
        color->setTransform(density->transform().copy());
        for (auto it = density->cbeginValueOn(); it; ++it) color->tree().setValue(it.getCoord(), Vec3s(*it, 0.5f, 1.0f - *it));
        vdbexport::writeVdbAtomic(add("bake_like.vdb").string(), {density, halo, color});
    }
    // 6. Every registered value type, active and inactive tiles, an instance, mask-compression
    // cases (one and two inactive values, -background), no compression, an empty grid.
    {
        GridPtrVec grids;
        auto f = FloatGrid::create(2.0f);
        f->setName("float_tiles");
        f->tree().addTile(2, Coord(0), 3.0f, true);    // active internal tile (128³)
        f->tree().addTile(3, Coord(8192), 4.0f, false); // inactive root tile
        auto acc = f->getAccessor();
        acc.setValue(Coord(200, 3, 4), 1.0f);
        acc.setValueOff(Coord(201, 3, 4), 5.0f); // one inactive value besides the background
        acc.setValue(Coord(300, 0, 0), 1.0f);
        acc.setValueOff(Coord(301, 0, 0), 5.0f); // two distinct inactive values
        acc.setValueOff(Coord(302, 0, 0), 7.0f);
        acc.setValue(Coord(400, 0, 0), 1.0f);
        acc.setValueOff(Coord(401, 0, 0), -2.0f); // -background
        grids.push_back(f);
        auto inst = f->copyGrid(); // shares the tree: written as an instance
        inst->setName("float_instance");
        grids.push_back(inst);
        auto d = DoubleGrid::create(0.0);
        d->setName("double");
        d->tree().setValue(Coord(-9, 5, 17), 1e300);
        grids.push_back(d);
        auto i32 = Int32Grid::create(0);
        i32->setName("int32");
        i32->tree().setValue(Coord(1, 2, 3), -7);
        grids.push_back(i32);
        auto i64 = Int64Grid::create(0);
        i64->setName("int64");
        i64->tree().setValue(Coord(1, 2, 3), int64_t(1) << 40);
        grids.push_back(i64);
        auto b = BoolGrid::create(false);
        b->setName("bool");
        b->tree().setValue(Coord(5, 5, 5), true);
        b->tree().setValueOn(Coord(6, 5, 5), false);
        b->tree().addTile(2, Coord(1024), true, true);
        grids.push_back(b);
        auto m = MaskGrid::create(false);
        m->setName("mask");
        m->tree().setValueOn(Coord(-100, 7, 7));
        grids.push_back(m);
        auto v3d = Vec3DGrid::create(Vec3d(0.0));
        v3d->setName("vec3d");
        v3d->tree().setValue(Coord(0, 0, 0), Vec3d(1, 2, 3));
        v3d->setSaveFloatAsHalf(true);
        grids.push_back(v3d);
        auto v3i = Vec3IGrid::create(Vec3i(0));
        v3i->setName("vec3i");
        v3i->tree().setValue(Coord(0, 0, 0), Vec3i(1, 2, 3));
        grids.push_back(v3i);
        auto empty = FloatGrid::create(0.0f);
        empty->setName("empty");
        grids.push_back(empty);
        auto nonlinear = FloatGrid::create(0.0f);
        nonlinear->setName("frustum");
        nonlinear->setTransform(math::Transform::createFrustumTransform(BBoxd(Vec3d(0), Vec3d(8)), 0.5, 2.0, 0.25));
        nonlinear->tree().setValue(Coord(1, 1, 1), 1.0f);
        grids.push_back(nonlinear);
        writePlain(add("all_types_blosc.vdb"), grids, io::COMPRESS_BLOSC | io::COMPRESS_ACTIVE_MASK);
        writePlain(add("all_types_none.vdb"), grids, io::COMPRESS_NONE);
        writePlain(add("all_types_zip_nomask.vdb"), grids, io::COMPRESS_ZIP);
    }
    // 7. A streamed file (io::Stream): no grid offsets, grids follow their descriptors.
    {
        const lic::PresetField f = lic::makePresetField("abc", Coord(res));
        std::ofstream os(add("streamed.vdb"), std::ios::binary);
        io::Stream(os).write({f.velocity});
    }
    return out;
}

} // namespace vdb_samples

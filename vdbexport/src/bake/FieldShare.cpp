#include "FieldShare.h"

#include "Distribute.h"
#include "lic/field/ScalarField.h"

#include "io/DenseCommon.h"
#include "vdbexport/io/FieldGrids.h"
#include "vdbexport/io/InputFormats.h"
#include "vdbexport/io/ReadCheck.h"
#include "vdbexport/io/VdbReader.h"

#include "lic/engine/Engine.h"
#include "lic/util/Error.h"

#include <openvdb/io/File.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace vdbexport::pipeline {

namespace {

const std::string kVec3s = openvdb::typeNameAsString<openvdb::Vec3s>();
const std::string kFloat = openvdb::typeNameAsString<float>();
const std::string kDouble = openvdb::typeNameAsString<double>();

/// Why this recipe and field must be read whole on every rank ("" when a part will do); the
/// velocity grid's name in `velName`. Resolves the grid as readVelocityGrid() does, and leaves
/// every case it would convert or combine (vec3d, split components) to the whole read.
std::string wholeReadReason(const Recipe& r, std::string& velName)
{
    std::string format;
    try {
        format = resolveInputFormat(r.field.path, r.field.format);
    } catch (const lic::InputError&) {
        return "the field's format is not known"; // the whole read reports it
    }
    if (findInputFormat(format)->kind != InputKind::Grid) return "a ." + format + " field has no partial read";
    if (r.field.crop) return "field.crop needs the whole field";
    if (r.field.resample) return "field.resample needs the whole field";
    if (r.field.mask == "zero") return "field.mask \"zero\" needs the whole field";
    if (r.field.nanPolicy == "zero") return "field.nan_policy \"zero\" needs the whole field";
    if (r.input.surface) return "input.surface places spots over the whole field";

    detail::VdbReader reader(r.field.path);
    const auto grids = reader.gridTypes();
    auto typeOf = [&](const std::string& n) -> std::string {
        for (const auto& [name, type] : grids)
            if (name == n) return type;
        return "";
    };
    if (!r.field.grid.empty()) {
        velName = r.field.grid;
    } else {
        for (const char* n : kDefaultVelocityNames)
            if (velName.empty() && detail::isVec3Type(typeOf(n))) velName = n;
        if (velName.empty()) {
            std::vector<std::string> vec3;
            for (const auto& [name, type] : grids)
                if (detail::isVec3Type(type)) vec3.push_back(name);
            if (vec3.size() == 1) velName = vec3.front();
        }
    }
    if (velName.empty() || typeOf(velName) != kVec3s) return "the velocity is not one vec3s grid";
    for (const auto& [name, type] : grids) {
        if (type == kDouble) return "the field file has double-precision scalar grids";
        if (std::count_if(grids.begin(), grids.end(), [&](const auto& g) { return g.first == name; }) > 1)
            return "the field file has two grids named " + name;
    }
    return "";
}

/// Index box (of a grid with transform `xform`) that holds the world box `world`, grown by `pad` voxels.
openvdb::CoordBBox indexBoxOf(const openvdb::math::Transform& xform, const openvdb::BBoxd& world, int pad)
{
    openvdb::Vec3d lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d w((c & 1) ? world.max()[0] : world.min()[0], (c & 2) ? world.max()[1] : world.min()[1],
                               (c & 4) ? world.max()[2] : world.min()[2]);
        const openvdb::Vec3d i = xform.worldToIndex(w);
        lo = openvdb::math::minComponent(lo, i);
        hi = openvdb::math::maxComponent(hi, i);
    }
    auto clampInt = [](double v) { return int(std::clamp(v, -1e9, 1e9)); };
    return openvdb::CoordBBox(
        openvdb::Coord(clampInt(std::floor(lo[0])) - pad, clampInt(std::floor(lo[1])) - pad, clampInt(std::floor(lo[2])) - pad),
        openvdb::Coord(clampInt(std::ceil(hi[0])) + pad, clampInt(std::ceil(hi[1])) + pad, clampInt(std::ceil(hi[2])) + pad));
}

/// World box of an index box's voxel extents.
openvdb::BBoxd worldBoxOf(const openvdb::math::Transform& xform, const openvdb::CoordBBox& box)
{
    return xform.indexToWorld(openvdb::BBoxd(box.min().asVec3d() - openvdb::Vec3d(0.5), box.max().asVec3d() + openvdb::Vec3d(0.5)));
}

double localMaxSpeed(const openvdb::Vec3SGrid& grid)
{
    openvdb::tree::LeafManager<const openvdb::Vec3STree> leaves(grid.tree());
    double m = tbb::parallel_reduce(
        leaves.leafRange(), 0.0,
        [](const auto& range, double acc) {
            for (auto leaf = range.begin(); leaf; ++leaf)
                for (auto it = leaf->cbeginValueOn(); it; ++it)
                    if (std::isfinite((*it)[0]) && std::isfinite((*it)[1]) && std::isfinite((*it)[2]))
                        acc = std::max(acc, double(it->length()));
            return acc;
        },
        [](double a, double b) { return std::max(a, b); });
    for (auto it = grid.tree().cbeginValueOn(); it; ++it) // active tiles
        if (!it.isVoxelValue() && std::isfinite((*it)[0]) && std::isfinite((*it)[1]) && std::isfinite((*it)[2]))
            m = std::max(m, double(it->length()));
    return m;
}

/// The part of a distributed bake: topology, domain, share, then the clipped grids.
void readPart(const Plan& plan, int rank, int ranks, const std::string& velName, int extra, FieldShare& s)
{
    const Recipe& r = plan.recipe;
    const std::string& path = r.field.path;
    // The same read defences as every other read (docs/inputs.md): the whole file's structure
    // checked, then read once in a child process, before OpenVDB opens it here (remembered for the
    // unchanged file: wholeReadReason() already did it through a VdbReader). Grids of types
    // licvdb does not read are never touched.
    const VdbCheckResult check = detail::checkedVdb(path);
    auto unreadable = [&](const std::string& name) {
        for (const auto& g : check.grids)
            if (g.name == name && !g.skipReason.empty()) return true;
        return false;
    };
    if (unreadable(velName)) throw lic::InputError("grid " + detail::q(velName) + " in " + detail::q(path) + " cannot be read");
    openvdb::io::File file(path);
    try {
        const detail::QuietNewerFormat quiet(check.fileVersion);
        file.open(/*delayLoad=*/true);
    } catch (const std::exception& e) {
        throw lic::InputError("cannot open " + detail::q(path) + " as a .vdb file: " + e.what());
    }

    // The whole grid's topology: with delayed loading, value masks without values.
    openvdb::math::Transform::Ptr xform;
    openvdb::MaskGrid::Ptr activity;
    openvdb::GridClass gridClass;
    {
        auto whole = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid(velName));
        if (!whole) throw lic::InputError("grid " + detail::q(velName) + " in " + detail::q(path) + " is not a vec3s grid");
        xform = whole->transform().copy();
        gridClass = whole->getGridClass();
        activity = openvdb::MaskGrid::create(std::make_shared<openvdb::MaskTree>(whole->tree(), false, openvdb::TopologyCopy()));
    }
    const openvdb::CoordBBox box = activity->evalActiveVoxelBoundingBox();
    s.extent.activeBox = box;
    s.extent.activeVoxels = activity->activeVoxelCount();
    if (s.extent.activeVoxels == 0)
        throw lic::InputError(detail::q(path) + ": grid " + detail::q(velName) + " has no active voxels; expected a field with data");
    if (box.dim()[0] <= 1 && box.dim()[1] <= 1 && box.dim()[2] <= 1)
        throw lic::InputError(detail::q(path) + ": grid " + detail::q(velName)
                              + " has a single active voxel; expected a field at least 2 voxels long on some axis");

    const int K = r.output.upsample;
    s.domain = std::make_unique<lic::OutputDomain>(*xform, box, *activity, K);
    activity.reset();
    s.layout = std::make_unique<lic::BrickLayout>(*s.domain, lic::brickDim(plan.settings));
    s.assignment = assignBricks(*s.layout, ranks);
    s.mine = bricksOf(s.assignment, rank);

    // The part: this rank's bricks (output voxels) in field voxels, grown by the margin.
    openvdb::CoordBBox region;
    if (s.mine.empty()) {
        region = openvdb::CoordBBox(box.min(), box.min()); // nothing to convolve: one voxel
    } else {
        openvdb::CoordBBox out;
        for (std::size_t id : s.mine) out.expand((*s.layout)[id].box);
        out.intersect(s.domain->indexBBox());
        const int m = fieldMargin(plan, K, lic::detail::integrationStride(*s.domain, plan.settings)) + std::max(0, extra);
        region = openvdb::CoordBBox(
            openvdb::Coord(lic::detail::floorDiv(out.min()[0], K), lic::detail::floorDiv(out.min()[1], K),
                           lic::detail::floorDiv(out.min()[2], K)),
            openvdb::Coord(lic::detail::floorDiv(out.max()[0], K), lic::detail::floorDiv(out.max()[1], K),
                           lic::detail::floorDiv(out.max()[2], K)))
                     .expandBy(m);
    }
    s.extent.region = region;

    // The velocity, clipped exactly to the part.
    const openvdb::BBoxd world = worldBoxOf(*xform, region);
    auto vel = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid(velName, worldBoxOf(*xform, region.expandBy(1))));
    if (!vel) throw lic::InputError("grid " + detail::q(velName) + " in " + detail::q(path) + " could not be read");
    vel->tree().clip(region);
    vel->setGridClass(gridClass);
    lic::setPartOf(*vel, box, region);
    s.extent.maxSpeed = localMaxSpeed(*vel);
    s.loaded.velocity = vel;
    s.loaded.gridName = velName;
    s.loaded.format = "vdb";

    // The file's float grids over the same world box (each in its own index space).
    const openvdb::GridPtrVecPtr metas = file.readAllGridMetadata(); // kept: the loop refers into it
    for (const auto& meta : *metas) {
        if (meta->valueType() != kFloat) continue;
        const std::string name = meta->getName();
        if (unreadable(name)) continue;
        auto whole = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(name)); // topology (delayed)
        const openvdb::CoordBBox wholeBox = whole->evalActiveVoxelBoundingBox();
        const openvdb::math::Transform::Ptr sx = whole->transform().copy();
        whole.reset();
        const openvdb::CoordBBox part = indexBoxOf(*sx, world, 2);
        auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(name, worldBoxOf(*sx, part.expandBy(1))));
        if (!g) continue;
        g->tree().clip(part);
        lic::setPartOf(*g, wholeBox, part);
        s.loaded.scalars.emplace(name, std::move(g));
    }
    file.close();
}

} // namespace

double spotReach(const Plan& plan) { return lic::spotReach(plan.settings, plan.maxSpotRadius); }

int fieldMargin(const Plan& plan, int upsample, int stride)
{
    const Recipe& r = plan.recipe;
    // Output voxels past the brick at which the engine samples the field; then field voxels: that,
    // one for the trilinear footprint and one for a staggered grid's next face; with scalars, two
    // for a derived scalar's one-sided differences, two for the gradient of a scalar and one for
    // the scalar probes' trilinear footprint.
    const double out = lic::fieldReach(plan.settings, plan.spots, plan.maxSpotRadius, stride);
    const bool scalars = r.width || r.color || r.roi || r.input.surface;
    return int(std::ceil(out / upsample)) + 2 + (scalars ? 5 : 0);
}

FieldShare readFieldShare(const Plan& plan, int rank, int ranks, const std::string& whole, int extra)
{
    const Recipe& r = plan.recipe;
    FieldShare s;
    std::string velName;
    if (ranks > 1) {
        s.wholeReason = whole.empty() ? wholeReadReason(r, velName) : whole;
        if (s.wholeReason.empty()) {
            s.partial = true;
            readPart(plan, rank, ranks, velName, extra, s);
            return s;
        }
    }
    s.loaded = loadField(r.field);
    if (!s.loaded.warnings.empty()) { // a field with no flow to draw (OpenFOAM: zero, uniform, only 0/)
        std::string what;
        for (const auto& w : s.loaded.warnings) what += (what.empty() ? "" : "; ") + w;
        throw lic::InputError("'" + r.field.path + "': " + what + ". bake refuses it (`licvdb convert` writes it "
                              "with this warning, and bake reads the .vdb it writes)");
    }
    s.field = std::make_unique<lic::VelocityField>(s.loaded.velocity);
    s.domain = std::make_unique<lic::OutputDomain>(*s.field, r.output.upsample);
    s.layout = std::make_unique<lic::BrickLayout>(*s.domain, lic::brickDim(plan.settings));
    s.assignment = assignBricks(*s.layout, ranks);
    s.mine = bricksOf(s.assignment, rank);
    const openvdb::Coord d = s.field->indexBBox().dim();
    s.voxelsHeld = std::uint64_t(d[0]) * std::uint64_t(d[1]) * std::uint64_t(d[2]);
    return s;
}

void makeField(FieldShare& s, double maxSpeed)
{
    s.extent.maxSpeed = maxSpeed;
    s.field = std::make_unique<lic::VelocityField>(s.loaded.velocity, s.extent);
    openvdb::CoordBBox dense = s.extent.activeBox;
    dense.intersect(s.extent.region);
    const openvdb::Coord d = dense.dim();
    s.voxelsHeld = std::uint64_t(d[0]) * std::uint64_t(d[1]) * std::uint64_t(d[2]);
}

} // namespace vdbexport::pipeline

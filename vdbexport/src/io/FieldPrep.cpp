// Field preparation: NaN/Inf policy, world-space crop, zero mask, resampling.
#include "vdbexport/io/FieldInput.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <openvdb/tools/Activate.h>
#include <openvdb/tools/GridTransformer.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace vdbexport {

using namespace detail;

namespace {

std::string vecText(const openvdb::Vec3d& v)
{
    std::ostringstream s;
    s << "(" << v[0] << ", " << v[1] << ", " << v[2] << ")";
    return s.str();
}

std::string coordText(const openvdb::Coord& c)
{
    return "(" + std::to_string(c[0]) + ", " + std::to_string(c[1]) + ", " + std::to_string(c[2]) + ")";
}

bool finite(const openvdb::Vec3s& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

/// Count NaN/Inf active values; optionally replace them with zero. Returns the count and the
/// lexicographically first offending voxel.
std::uint64_t scanNonFinite(openvdb::Vec3SGrid& grid, bool replace, openvdb::Coord& first)
{
    std::uint64_t bad = 0;
    first = openvdb::Coord::max();
    for (auto it = grid.tree().beginValueOn(); it; ++it) {
        if (finite(*it)) continue;
        bad += it.getVoxelCount();
        if (it.getCoord() < first) first = it.getCoord();
        if (replace) it.setValue(openvdb::Vec3s(0.0f));
    }
    return bad;
}

/// A cell-centred copy of a staggered (MAC) grid: component a of voxel (i,j,k) is the mean of
/// the faces at i-½ (stored in voxel i) and i+½ (stored in voxel i+1) along axis a.
openvdb::Vec3SGrid::Ptr staggeredToCentred(const openvdb::Vec3SGrid& in)
{
    auto out = in.deepCopy();
    auto acc = in.getConstAccessor();
    for (auto it = out->tree().beginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (!it.isVoxelValue()) continue; // constant tiles: the mean is the value itself
        const openvdb::Vec3s v = acc.getValue(c);
        openvdb::Vec3s r;
        for (int a = 0; a < 3; ++a) {
            openvdb::Coord n = c;
            n[a] += 1;
            r[a] = 0.5f * (v[a] + acc.getValue(n)[a]);
        }
        it.setValue(r);
    }
    out->setGridClass(openvdb::GRID_UNKNOWN);
    return out;
}

} // namespace

void prepareField(const FieldSpec& spec, const std::string& source, LoadedField& field)
{
    if (!field.velocity) throw lic::InputError(q(source) + ": no velocity grid");
    auto& grid = field.velocity;
    if (!grid->transform().isLinear())
        throw lic::InputError(q(source) + ": the field's transform is not linear (map " + grid->transform().mapType()
                              + "); expected an affine index-to-world map");

    // 1. NaN / Inf.
    openvdb::Coord first;
    const bool replace = spec.nanPolicy == "zero";
    const std::uint64_t bad = scanNonFinite(*grid, replace, first);
    if (bad > 0 && !replace) {
        throw lic::InputError(q(source) + ": grid " + q(field.gridName) + " has " + std::to_string(bad)
                              + " NaN or infinite value(s); the first at voxel " + coordText(first) + ", world "
                              + vecText(grid->indexToWorld(first))
                              + "; fix the data, or pass --nan-policy zero (field.nan_policy \"zero\") to treat them as 0");
    }
    if (bad > 0) {
        field.nonFiniteReplaced = bad;
        field.notes.push_back("replaced " + std::to_string(bad) + " NaN/Inf value(s) of grid '" + field.gridName
                              + "' with 0 (first at voxel " + coordText(first) + ", world "
                              + vecText(grid->indexToWorld(first)) + ")");
    }

    // 2. Crop to a world-space box: keep voxels whose centres lie inside.
    if (spec.crop) {
        const auto& c = *spec.crop;
        openvdb::Vec3d lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
        for (int corner = 0; corner < 8; ++corner) {
            const openvdb::Vec3d w(c[(corner & 1) ? 1 : 0][0], c[(corner & 2) ? 1 : 0][1], c[(corner & 4) ? 1 : 0][2]);
            const openvdb::Vec3d idx = grid->worldToIndex(w);
            lo = openvdb::math::minComponent(lo, idx);
            hi = openvdb::math::maxComponent(hi, idx);
        }
        const openvdb::CoordBBox before = grid->evalActiveVoxelBoundingBox();
        const openvdb::BBoxd worldBefore = grid->transform().indexToWorld(
            openvdb::BBoxd(before.min().asVec3d() - 0.5, before.max().asVec3d() + 0.5));
        auto clamp = [](double v) { return int(std::clamp(v, -1e9, 1e9)); };
        const openvdb::CoordBBox keep(openvdb::Coord(clamp(std::ceil(lo[0] - 1e-9)), clamp(std::ceil(lo[1] - 1e-9)),
                                                     clamp(std::ceil(lo[2] - 1e-9))),
                                      openvdb::Coord(clamp(std::floor(hi[0] + 1e-9)), clamp(std::floor(hi[1] + 1e-9)),
                                                     clamp(std::floor(hi[2] + 1e-9))));
        if (keep.empty() || !keep.hasOverlap(before)) {
            throw lic::InputError(q(source) + ": crop box " + vecText({c[0][0], c[0][1], c[0][2]}) + " - "
                                  + vecText({c[1][0], c[1][1], c[1][2]}) + " holds no voxel centre of the field, whose world bounds are "
                                  + vecText(worldBefore.min()) + " - " + vecText(worldBefore.max()));
        }
        grid->tree().clip(keep);
        // Scalar grids are sampled in world space by the bake: they need no crop.
        field.notes.push_back("cropped the field to voxels " + coordText(keep.min()) + " - " + coordText(keep.max()));
    }

    // 3. Mask: zero-velocity voxels become inactive (tight bounds for dense inputs).
    if (spec.mask == "zero") {
        const auto before = grid->activeVoxelCount();
        openvdb::tools::deactivate(*grid, openvdb::Vec3s(0.0f), openvdb::Vec3s(0.0f));
        openvdb::tools::pruneInactive(grid->tree());
        field.notes.push_back("masked " + std::to_string(before - grid->activeVoxelCount()) + " zero-velocity voxel(s)");
    }

    if (grid->activeVoxelCount() == 0)
        throw lic::InputError(q(source) + ": grid " + q(field.gridName) + " has no active voxels"
                              + (spec.crop || spec.mask == "zero" ? " after cropping/masking" : "")
                              + "; expected a field with data");

    // 4. Resample to a target voxel size (trilinear; a staggered grid is first made cell-centred).
    if (spec.resample) {
        const double vs = *spec.resample;
        const openvdb::Vec3d srcVs = grid->voxelSize();
        const openvdb::CoordBBox bb = grid->evalActiveVoxelBoundingBox();
        const openvdb::Vec3d ext = openvdb::Vec3d(bb.dim().asVec3d()) * srcVs;
        const double newVoxels = std::ceil(ext[0] / vs) * std::ceil(ext[1] / vs) * std::ceil(ext[2] / vs);
        if (newVoxels > double(kMaxDenseVoxels))
            throw lic::InputError("field.resample: voxel size " + std::to_string(vs) + " would give about "
                                  + std::to_string(std::uint64_t(newVoxels)) + " voxels (limit "
                                  + std::to_string(kMaxDenseVoxels) + "); choose a larger voxel size");
        openvdb::Vec3SGrid::Ptr src = grid->getGridClass() == openvdb::GRID_STAGGERED ? staggeredToCentred(*grid) : grid;
        // New voxel centres start at the world position of the old first voxel centre.
        const openvdb::Vec3d start = grid->indexToWorld(bb.min());
        auto xform = openvdb::math::Transform::createLinearTransform(vs);
        xform->postTranslate(start);
        auto dst = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
        dst->setTransform(xform);
        openvdb::tools::resampleToMatch<openvdb::tools::BoxSampler>(*src, *dst);
        // Keep new voxel centres within the old centres' box: beyond it the sampler blends in
        // the zero background and would weaken the flow at the border.
        {
            const openvdb::Vec3d a = dst->worldToIndex(grid->indexToWorld(bb.min()));
            const openvdb::Vec3d b = dst->worldToIndex(grid->indexToWorld(bb.max()));
            const openvdb::Vec3d lo = openvdb::math::minComponent(a, b), hi = openvdb::math::maxComponent(a, b);
            dst->tree().clip(openvdb::CoordBBox(
                openvdb::Coord(int(std::ceil(lo[0] - 1e-6)), int(std::ceil(lo[1] - 1e-6)), int(std::ceil(lo[2] - 1e-6))),
                openvdb::Coord(int(std::floor(hi[0] + 1e-6)), int(std::floor(hi[1] + 1e-6)), int(std::floor(hi[2] + 1e-6)))));
        }
        static_cast<openvdb::MetaMap&>(*dst) = static_cast<const openvdb::MetaMap&>(*src);
        dst->setGridClass(openvdb::GRID_UNKNOWN);
        dst->setTransform(xform);
        grid = dst;
        field.notes.push_back("resampled the field from voxel size " + vecText(srcVs) + " to " + std::to_string(vs));
        if (grid->activeVoxelCount() == 0)
            throw lic::InputError("field.resample: voxel size " + std::to_string(vs) + " leaves no active voxel; choose a smaller voxel size");
    }

    const openvdb::CoordBBox bb = grid->evalActiveVoxelBoundingBox();
    if (bb.dim()[0] <= 1 && bb.dim()[1] <= 1 && bb.dim()[2] <= 1)
        throw lic::InputError(q(source) + ": grid " + q(field.gridName)
                              + " has a single active voxel; expected a field at least 2 voxels long on some axis");
}

} // namespace vdbexport

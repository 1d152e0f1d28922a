// Reading a velocity field and scalar grids (FieldGrids.h): grids of other precisions converted,
// split velocity components (`vel.x`, `vel.y`, `vel.z`) combined into one Vec3 grid.
#include "vdbexport/io/FieldGrids.h"

#include "vdbexport/io/VdbReader.h"
#include "Quote.h"

#include <lic/util/Error.h>

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/ValueTransformer.h>
#include <openvdb/tree/LeafManager.h>

#include <algorithm>
#include <sstream>

namespace vdbexport {

namespace {

using detail::q;

/// Copy name, class, metadata and transform of `src` onto `dst`.
void copyGridAttributes(const openvdb::GridBase& src, openvdb::GridBase& dst)
{
    static_cast<openvdb::MetaMap&>(dst) = static_cast<const openvdb::MetaMap&>(src);
    dst.setTransform(src.constTransform().copy());
}

/// A value converted to another value type (double → float, Vec3d → Vec3s, Vec3i → Vec3s).
/// OpenVDB's value-converting tree constructor refuses Vec3d → Vec3s, so convert by hand.
template<typename DstV, typename SrcV>
DstV convertValue(const SrcV& v)
{
    if constexpr (openvdb::VecTraits<SrcV>::IsVec) {
        using E = typename openvdb::VecTraits<DstV>::ElementType;
        return DstV(static_cast<E>(v[0]), static_cast<E>(v[1]), static_cast<E>(v[2]));
    } else {
        return static_cast<DstV>(v);
    }
}

/// A copy of `src` with another value type: same topology, every voxel and tile value (active
/// or not) converted, and the same name, class, metadata and transform.
template<typename DstGridT, typename SrcGridT>
typename DstGridT::Ptr convertGrid(const SrcGridT& src)
{
    using DstTreeT = typename DstGridT::TreeType;
    using DstV = typename DstGridT::ValueType;
    auto tree = std::make_shared<DstTreeT>(src.tree(), convertValue<DstV>(src.background()),
                                           openvdb::TopologyCopy());
    // Leaf voxels, in parallel.
    openvdb::tree::LeafManager<DstTreeT> leaves(*tree);
    leaves.foreach([&](typename DstTreeT::LeafNodeType& leaf, std::size_t) {
        const auto* srcLeaf = src.tree().probeConstLeaf(leaf.origin());
        if (!srcLeaf) return;
        for (openvdb::Index i = 0; i < DstTreeT::LeafNodeType::SIZE; ++i)
            leaf.setValueOnly(i, convertValue<DstV>(srcLeaf->getValue(i)));
    });
    // Tiles of the root and internal nodes.
    auto srcAcc = src.getConstAccessor();
    auto it = tree->beginValueAll();
    it.setMaxDepth(DstTreeT::RootNodeType::LEVEL - 1);
    for (; it; ++it) it.setValue(convertValue<DstV>(srcAcc.getValue(it.getCoord())));

    auto dst = DstGridT::create(tree);
    copyGridAttributes(src, *dst);
    return dst;
}

openvdb::Vec3SGrid::Ptr toVec3S(const openvdb::GridBase::Ptr& grid)
{
    if (auto g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(grid)) return g;
    if (auto g = openvdb::gridConstPtrCast<openvdb::Vec3DGrid>(grid))
        return convertGrid<openvdb::Vec3SGrid>(*g);
    if (auto g = openvdb::gridConstPtrCast<openvdb::Vec3IGrid>(grid))
        return convertGrid<openvdb::Vec3SGrid>(*g);
    return nullptr;
}

openvdb::FloatGrid::Ptr toFloat(const openvdb::GridBase::Ptr& grid)
{
    if (auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(grid)) return g;
    if (auto g = openvdb::gridConstPtrCast<openvdb::DoubleGrid>(grid))
        return convertGrid<openvdb::FloatGrid>(*g);
    return nullptr;
}

} // namespace

namespace detail {

bool isVec3Type(const std::string& valueType)
{
    return valueType == openvdb::typeNameAsString<openvdb::Vec3s>()
        || valueType == openvdb::typeNameAsString<openvdb::Vec3d>()
        || valueType == openvdb::typeNameAsString<openvdb::Vec3i>();
}

} // namespace detail

namespace {

bool isScalarType(const std::string& t)
{
    return t == openvdb::typeNameAsString<float>() || t == openvdb::typeNameAsString<double>();
}

using GridList = std::vector<std::pair<std::string, std::string>>;

/// True if `grids` has a scalar grid called `name`.
bool hasScalarGrid(const GridList& grids, const std::string& name)
{
    return std::any_of(grids.begin(), grids.end(), [&](const auto& g) { return g.first == name && isScalarType(g.second); });
}

/// The base names that split components are looked for under: `only` if given, else `velocity`,
/// `vel`, `v`, then the base `b` of every grid `b.x` or `b_x` (with `anyAxis`, `b.?` or `b_?`).
std::vector<std::string> splitBases(const GridList& grids, const std::string& only, bool anyAxis)
{
    if (!only.empty()) return {only};
    std::vector<std::string> bases;
    for (const char* n : kDefaultVelocityNames) bases.emplace_back(n);
    for (const auto& g : grids) {
        const std::string& n = g.first;
        if (n.size() <= 2 || (n[n.size() - 2] != '.' && n[n.size() - 2] != '_')) continue;
        if (anyAxis || n.back() == 'x') bases.push_back(n.substr(0, n.size() - 2));
    }
    return bases;
}

/// The base name `b` for which `b.x`, `b.y`, `b.z` (or `b_x`…) are all scalar grids of the file,
/// preferring `velocity`, `vel`, `v`; "" if there is none. `sep` receives the separator.
std::string findSplitBase(const GridList& grids, const std::string& only, std::string& sep)
{
    const auto has = [&](const std::string& n) { return hasScalarGrid(grids, n); };
    for (const auto& b : splitBases(grids, only, /*anyAxis=*/false))
        for (const char* sp : {".", "_"})
            if (has(b + sp + "x") && has(b + sp + "y") && has(b + sp + "z")) {
                sep = sp;
                return b;
            }
    return "";
}

/// For a base name with some but not all of its split components (`vel.x`, `vel.y` without
/// `vel.z`): " (split components 'vel.x', 'vel.y' found, 'vel.z' missing)"; "" otherwise.
/// `only` = "" looks at the default names (velocity, vel, v) and every `*.x`/`*_x` grid.
std::string partialSplitNote(const GridList& grids, const std::string& only)
{
    for (const auto& b : splitBases(grids, only, /*anyAxis=*/true))
        for (const char* sp : {".", "_"}) {
            std::string found, missing;
            for (const char a : {'x', 'y', 'z'}) {
                const std::string n = b + sp + a;
                std::string& list = hasScalarGrid(grids, n) ? found : missing;
                list += (list.empty() ? "" : ", ") + q(n);
            }
            if (!found.empty() && !missing.empty())
                return " (split components " + found + " found, " + missing + " missing)";
        }
    return "";
}

/// Split components must share a voxel size and orientation (their linear maps equal up to the
/// translation): a face-centred (MAC) layout, offset by half a voxel, is sampled in world space;
/// components of different resolutions or rotations are refused rather than resampled.
/// @throw lic::InputError naming each component's voxel size.
void checkSplitTransforms(const openvdb::FloatGrid::Ptr (&comp)[3], const std::string (&names)[3], const std::string& path)
{
    const auto linear = [](const openvdb::FloatGrid& g) {
        openvdb::Mat4d m = g.transform().baseMap()->getAffineMap()->getMat4();
        m.setTranslation(openvdb::Vec3d(0.0));
        return m;
    };
    const openvdb::Mat4d m0 = linear(*comp[0]);
    if (linear(*comp[1]).eq(m0, 1e-12) && linear(*comp[2]).eq(m0, 1e-12)) return;
    std::ostringstream msg;
    msg << "split velocity components in " << q(path) << " have different transforms (";
    for (int a = 0; a < 3; ++a) msg << (a ? ", " : "") << q(names[a]) << " voxel size " << comp[a]->voxelSize();
    msg << "); the three grids must share one voxel size and orientation (offsets by part of a voxel, "
           "as in a face-centred layout, are allowed)";
    throw lic::InputError(msg.str());
}

/// The value of every active voxel of `out`: component a read from comp[a] at the same index
/// coordinate (`same` transforms), else sampled trilinearly at the voxel's world position.
/// Threaded (tools::foreach, a copy of the accessors per task); each value depends only on its voxel.
void fillFromComponents(openvdb::Vec3SGrid& out, const openvdb::FloatGrid::Ptr (&comp)[3], bool same)
{
    using Sampler = openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler>;
    struct Fill
    {
        openvdb::FloatGrid::ConstAccessor acc[3];
        const openvdb::FloatGrid::Ptr (&grids)[3];
        const openvdb::math::Transform& xform;
        bool same;
        void operator()(const openvdb::Vec3SGrid::ValueOnIter& it) const
        {
            openvdb::Vec3s v;
            const openvdb::Vec3d w = same ? openvdb::Vec3d(0.0) : xform.indexToWorld(it.getCoord());
            for (int a = 0; a < 3; ++a)
                v[a] = same ? acc[a].getValue(it.getCoord()) : Sampler(acc[a], grids[a]->transform()).wsSample(w);
            it.setValue(v);
        }
    };
    // Not const: a const op would be shared by the threads, and accessors cache per thread.
    Fill fill{{comp[0]->getConstAccessor(), comp[1]->getConstAccessor(), comp[2]->getConstAccessor()},
              comp, out.transform(), same};
    openvdb::tools::foreach(out.beginValueOn(), fill, /*threaded=*/true, /*shared=*/false);
}

/// One Vec3 grid from three scalar component grids (Houdini's and EmberGen's split `vel.x`,
/// `vel.y`, `vel.z`). The result has the x grid's transform and the union of the three active
/// regions (tools: topologyUnion); components offset by part of a voxel (face-centred, MAC style)
/// are sampled trilinearly at the result's voxel centres in world space.
/// @throw lic::InputError for a component that is not a scalar grid, a non-linear transform, or
///        components of different voxel sizes or orientations (checkSplitTransforms).
openvdb::Vec3SGrid::Ptr combineSplit(detail::VdbReader& reader, const std::string& base, const std::string& sep)
{
    openvdb::FloatGrid::Ptr comp[3];
    const std::string names[3] = {base + sep + "x", base + sep + "y", base + sep + "z"};
    for (int a = 0; a < 3; ++a) {
        comp[a] = toFloat(reader.readGrid(names[a]));
        if (!comp[a]) throw lic::InputError("grid " + q(names[a]) + " in " + q(reader.path()) + " is not a scalar grid");
        if (!comp[a]->transform().isLinear())
            throw lic::InputError("grid " + q(names[a]) + " in " + q(reader.path()) + " has a non-linear transform");
    }
    checkSplitTransforms(comp, names, reader.path());
    auto out = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    out->setTransform(comp[0]->transform().copy());
    out->setName(base);
    out->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    const bool sameXform = comp[1]->transform() == comp[0]->transform() && comp[2]->transform() == comp[0]->transform();
    for (int a = 0; a < 3; ++a) {
        if (sameXform) {
            out->tree().topologyUnion(comp[a]->tree());
            continue;
        }
        const openvdb::CoordBBox bb = comp[a]->evalActiveVoxelBoundingBox();
        if (bb.empty()) continue;
        const openvdb::BBoxd w = comp[a]->transform().indexToWorld(bb);
        const openvdb::Vec3d lo = out->worldToIndex(w.min()), hi = out->worldToIndex(w.max());
        out->tree().sparseFill(openvdb::CoordBBox(openvdb::Coord::round(openvdb::math::minComponent(lo, hi)),
                                                  openvdb::Coord::round(openvdb::math::maxComponent(lo, hi))),
                               openvdb::Vec3s(0.0f), true);
    }
    out->tree().voxelizeActiveTiles();
    fillFromComponents(*out, comp, sameXform);
    return out;
}

} // namespace

openvdb::Vec3SGrid::Ptr readVelocityGrid(const std::string& path, const std::string& name,
                                         std::string* chosenName)
{
    detail::VdbReader reader(path);
    const auto grids = reader.gridTypes();
    const auto find = [&](const std::string& n) {
        return std::find_if(grids.begin(), grids.end(), [&](const auto& g) { return g.first == n; });
    };

    std::string chosen;
    if (!name.empty()) {
        const auto it = find(name);
        if (it == grids.end()) {
            std::string sep;
            if (!findSplitBase(grids, name, sep).empty()) {
                if (chosenName) *chosenName = name;
                return combineSplit(reader, name, sep);
            }
            throw lic::InputError("grid " + q(name) + " not found in " + q(path) + partialSplitNote(grids, name)
                                  + "; the file has: " + detail::listGrids(grids));
        }
        if (!detail::isVec3Type(it->second))
            throw lic::InputError("grid " + q(name) + " in " + q(path) + " is a " + it->second
                                  + " grid; a " + it->second + " grid cannot be a velocity field "
                                  "(expected a Vec3 grid: vec3s, vec3d or vec3i)");
        chosen = name;
    } else {
        for (const char* candidate : kDefaultVelocityNames) {
            const auto it = find(candidate);
            if (it != grids.end() && detail::isVec3Type(it->second)) {
                chosen = candidate;
                break;
            }
        }
        if (chosen.empty()) {
            std::vector<std::pair<std::string, std::string>> vec3;
            for (const auto& g : grids)
                if (detail::isVec3Type(g.second)) vec3.push_back(g);
            std::string sep;
            const std::string split = vec3.empty() ? findSplitBase(grids, "", sep) : "";
            if (!split.empty()) {
                if (chosenName) *chosenName = split;
                return combineSplit(reader, split, sep);
            }
            if (vec3.empty())
                throw lic::InputError(q(path) + " has no Vec3 grid to use as a velocity field" + partialSplitNote(grids, "")
                                      + "; the file has: " + detail::listGrids(grids)
                                      + "; expected a vec3s, vec3d or vec3i grid, or float grids NAME.x, NAME.y, NAME.z");
            if (vec3.size() > 1)
                throw lic::InputError(q(path) + " has several Vec3 grids and none is named "
                                      "'velocity', 'vel' or 'v': " + detail::listGrids(vec3)
                                      + "; pass --grid NAME to choose one");
            chosen = vec3.front().first;
        }
    }

    auto grid = toVec3S(reader.readGrid(chosen));
    if (!grid)
        throw lic::InputError("grid " + q(chosen) + " in " + q(path)
                              + " could not be read as a Vec3 grid");
    if (chosenName) *chosenName = chosen;
    return grid;
}

std::map<std::string, openvdb::FloatGrid::Ptr> readScalarGrids(const std::string& path)
{
    detail::VdbReader reader(path);
    std::map<std::string, openvdb::FloatGrid::Ptr> out;
    for (const auto& [name, type] : reader.gridTypes()) {
        if (type != openvdb::typeNameAsString<float>() && type != openvdb::typeNameAsString<double>())
            continue;
        if (out.count(name)) continue; // duplicate name: the first one wins, as in readGrid
        if (auto grid = toFloat(reader.readGrid(name))) out.emplace(name, std::move(grid));
    }
    return out;
}

} // namespace vdbexport

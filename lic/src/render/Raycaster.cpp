#include "lic/render/Raycaster.h"

#include "LeafTable.h"
#include "lic/util/Error.h"
#include "lic/util/IndexMath.h"
#include "lic/util/Parallel.h"

#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Interpolation.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

namespace lic {

// ---- transfer -------------------------------------------------------------------------------

std::pair<double, double> lineShade(const Lighting& lt, const openvdb::Vec3d& t, const openvdb::Vec3d& l,
                                    const openvdb::Vec3d& v)
{
    const double lt1 = l.dot(t), vt = v.dot(t);
    const double sl = l.cross(t).length(); // = √(1 − (L·T)²) for unit vectors
    const double sv = v.cross(t).length(); // = √(1 − (V·T)²)
    const double vr = sl * sv - lt1 * vt;
    const double spec = vr > 0.0 ? std::pow(vr, lt.shininess) : 0.0;
    return {lt.ambient + lt.diffuse * sl, lt.specular * spec};
}

void RenderSettings::validate() const
{
    auto bad = [](const std::string& what, double v, const std::string& expected) {
        std::ostringstream msg;
        msg << what << " " << v << " is out of range; expected " << expected;
        return InputError(msg.str());
    };
    if (!(densityScale >= 0.0 && std::isfinite(densityScale))) throw bad("density scale", densityScale, "> 0 (or 0 = auto)");
    if (!(densityLow >= 0.0 && densityLow < 1.0)) throw bad("density window low", densityLow, "[0, 1)");
    if (!(densityHigh > densityLow && densityHigh <= 1e6)) throw bad("density window high", densityHigh, "> low");
    if (!(brightness >= 0.0 && std::isfinite(brightness))) throw bad("brightness", brightness, ">= 0");
    if (!(step > 0.0 && step <= 8.0)) throw bad("step", step, "voxels in (0, 8]");
    if (!(haloStrength >= 0.0 && std::isfinite(haloStrength))) throw bad("halo strength", haloStrength, ">= 0");
    if (!(haloThreshold >= 0.0 && haloThreshold < 1.0)) throw bad("halo threshold", haloThreshold, "[0, 1)");
    if (!(minTransmittance >= 0.0 && minTransmittance < 1.0))
        throw bad("minimum transmittance", minTransmittance, "[0, 1)");
    const double d = lighting.direction.length();
    if (!lighting.headlight && !(d > 0.0 && std::isfinite(d)))
        throw InputError("light direction is zero or not finite; expected a direction x,y,z towards the light");
    if (!(lighting.shininess >= 0.0)) throw bad("shininess", lighting.shininess, ">= 0");
}

// ---- the raycaster ---------------------------------------------------------------------------

namespace {

constexpr int kBrick = 8;
/// Auto density scale: the optical depth of an average ray across the box.
constexpr double kAutoDepth = 2.5;
/// Auto density scale of a line bake (one with a `halo` grid).
constexpr double kAutoLineScale = 2.0;
constexpr int kTile = 32;

template<typename T>
bool sameBits(const T& a, const T& b)
{
    return std::memcmp(&a, &b, sizeof(T)) == 0;
}

/// `grid` on the voxels of `target`'s index space: the grid itself when the transforms are equal
/// (shared, not copied); otherwise a new sparse grid that holds, at each voxel of `box`, the
/// trilinear world-space sample of `grid` at the voxel's centre. Its leaves are only the blocks
/// with a value other than `grid`'s background, which it takes as its own, so reading it anywhere
/// in `box` gives those samples.
template<typename GridT>
typename GridT::ConstPtr onVoxelsOf(const typename GridT::ConstPtr& grid, const openvdb::math::Transform& target,
                                    const openvdb::CoordBBox& box)
{
    if (grid->transform() == target) return grid;
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    constexpr int dim = int(LeafT::DIM);
    const ValueT bg = grid->background();
    const openvdb::Coord lo(box.min().x() & ~(dim - 1), box.min().y() & ~(dim - 1), box.min().z() & ~(dim - 1));
    const std::size_t n[3] = {std::size_t((box.max().x() - lo.x()) / dim + 1), std::size_t((box.max().y() - lo.y()) / dim + 1),
                              std::size_t((box.max().z() - lo.z()) / dim + 1)};
    std::vector<std::unique_ptr<LeafT>> leaves(n[0] * n[1] * n[2]);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
        auto acc = grid->getConstAccessor();
        openvdb::tools::GridSampler<decltype(acc), openvdb::tools::BoxSampler> sampler(acc, grid->transform());
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            const openvdb::Coord o =
                lo.offsetBy(int(b % n[0]) * dim, int(b / n[0] % n[1]) * dim, int(b / (n[0] * n[1])) * dim);
            openvdb::CoordBBox cell = openvdb::CoordBBox::createCube(o, dim);
            cell.intersect(box);
            std::unique_ptr<LeafT> leaf;
            for (auto ijk = cell.begin(); ijk; ++ijk) {
                const ValueT v = sampler.wsSample(target.indexToWorld((*ijk).asVec3d()));
                if (sameBits(v, bg)) continue;
                if (!leaf) leaf = std::make_unique<LeafT>(o, bg, false);
                leaf->setValueOn(*ijk, v);
            }
            leaves[b] = std::move(leaf);
        }
    });
    auto out = GridT::create(bg);
    out->setTransform(target.copy());
    out->setName(grid->getName());
    for (auto& leaf : leaves)
        if (leaf) out->tree().addLeaf(leaf.release());
    return out;
}

void requireLinear(const openvdb::GridBase& g)
{
    if (!g.transform().isLinear())
        throw InputError("grid '" + g.getName() + "' has a non-linear (frustum) transform; expected a linear transform");
}

/// @throw InputError if `vol` lacks a density grid, has a grid with a non-linear transform, or
///        `settings` ask for a colormap without a scalar grid.
void checkVolume(const RenderVolume& vol, const RenderSettings& settings)
{
    if (!vol.density) throw InputError("no density grid to render");
    requireLinear(*vol.density);
    for (const openvdb::GridBase* g : std::initializer_list<const openvdb::GridBase*>{
             vol.halo.get(), vol.color.get(), vol.scalar.get(), vol.tangent.get(), vol.flow.get()})
        if (g) requireLinear(*g);
    if (settings.colormap && !vol.scalar)
        throw InputError("a colormap needs a `scalar` grid to colour by, and there is none");
}

/// The active voxels of the density grid, and with halos of the halo grid, in density index space.
/// @throw InputError if there are none.
openvdb::CoordBBox activeBox(const RenderVolume& vol, const RenderSettings& settings,
                             const openvdb::math::Transform& xform)
{
    openvdb::CoordBBox active = vol.density->evalActiveVoxelBoundingBox();
    if (vol.halo && settings.halos) {
        // The halo's active box, in density index space.
        const openvdb::CoordBBox hb = vol.halo->evalActiveVoxelBoundingBox();
        if (!hb.empty()) {
            if (vol.halo->transform() == xform) active.expand(hb);
            else {
                const openvdb::BBoxd w = vol.halo->transform().indexToWorld(hb);
                const openvdb::BBoxd i = xform.worldToIndex(w);
                active.expand(openvdb::CoordBBox(openvdb::Coord::floor(i.min()), openvdb::Coord::ceil(i.max())));
            }
        }
    }
    if (active.empty() || vol.density->activeVoxelCount() == 0)
        throw InputError("grid '" + vol.density->getName() + "' has no active voxels; nothing to render");
    return active;
}

/// A table of `map` (scene-linear) with 1024 entries over [0, 1].
std::vector<openvdb::Vec3s> colormapTable(const Colormap& map)
{
    std::vector<openvdb::Vec3s> lut(1024);
    for (int i = 0; i < 1024; ++i) {
        const openvdb::Vec3d c = map.linear(double(i) / 1023.0);
        lut[std::size_t(i)] = openvdb::Vec3s(float(c[0]), float(c[1]), float(c[2]));
    }
    return lut;
}

/// `f(leaf)` for every leaf of `tree`, in parallel, and `g(bbox, value)` for every tile (active
/// or not; not the background outside the root's tiles), serially.
template<typename TreeT, typename F, typename G>
void forEachLeafAndTile(const TreeT& tree, const F& f, const G& g)
{
    std::vector<const typename TreeT::LeafNodeType*> leaves;
    tree.getNodes(leaves);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(*leaves[i]);
    });
    auto it = tree.cbeginValueAll();
    it.setMaxDepth(TreeT::ValueAllCIter::LEAF_DEPTH - 1);
    for (; it; ++it) {
        openvdb::CoordBBox b;
        it.getBoundingBox(b);
        g(b, *it);
    }
}

/// Σ clamp((v − lo)·inv, 0, 1) over the voxels of `box` (leaves, tiles and background alike), in
/// an order that does not depend on threads: leaf by leaf in the tree's order, then tiles, then
/// the background's voxels.
double windowedSum(const openvdb::FloatTree& tree, const openvdb::CoordBBox& box, double lo, double inv)
{
    auto w = [&](float v) { return std::clamp((double(v) - lo) * inv, 0.0, 1.0); };
    std::vector<const openvdb::FloatTree::LeafNodeType*> leaves;
    tree.getNodes(leaves);
    std::vector<double> sums(leaves.size(), 0.0);
    std::vector<std::uint64_t> counts(leaves.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            openvdb::CoordBBox b = leaves[i]->getNodeBoundingBox();
            const bool inside = box.isInside(b);
            b.intersect(box);
            if (b.empty()) continue;
            double acc = 0.0;
            if (inside) { // the usual case: the buffer in order
                const float* v = leaves[i]->buffer().data();
                for (int k = 0; k < 512; ++k) acc += w(v[k]);
            } else {
                for (auto ijk = b.begin(); ijk; ++ijk) acc += w(leaves[i]->getValue(*ijk));
            }
            sums[i] = acc;
            counts[i] = b.volume();
        }
    });
    double sum = 0.0;
    std::uint64_t counted = 0;
    for (std::size_t i = 0; i < leaves.size(); ++i) {
        sum += sums[i];
        counted += counts[i];
    }
    auto it = tree.cbeginValueAll();
    it.setMaxDepth(openvdb::FloatTree::ValueAllCIter::LEAF_DEPTH - 1);
    for (; it; ++it) {
        openvdb::CoordBBox b;
        it.getBoundingBox(b);
        b.intersect(box);
        if (b.empty()) continue;
        sum += double(b.volume()) * w(*it);
        counted += b.volume();
    }
    return sum + double(box.volume() - counted) * w(tree.background());
}

/// Which 8³ bricks of samples can contribute (empty-space skipping). Brick b (local index space,
/// local 0 = `origin`) covers samples [8b, 8b + 8) and reads voxels [8b, 8b + 8] of the box.
class BrickTable
{
public:
    BrickTable() = default;
    BrickTable(const openvdb::CoordBBox& box, const openvdb::Vec3d& extent) : mBox(box)
    {
        for (int a = 0; a < 3; ++a) mCount[a] = int(std::floor(extent[a] / kBrick)) + 1;
        mActive.assign(std::size_t(mCount[0]) * std::size_t(mCount[1]) * std::size_t(mCount[2]), 0);
    }
    int count(int axis) const { return mCount[axis]; }
    bool active(std::size_t brick) const { return mActive[brick] != 0; }

    /// Mark the bricks that read a voxel of `tree` above `threshold`.
    template<typename TreeT>
    void mark(const TreeT& tree, float threshold)
    {
        if (tree.background() > threshold) {
            std::fill(mActive.begin(), mActive.end(), std::uint8_t(1));
            return;
        }
        forEachLeafAndTile(
            tree, [&](const typename TreeT::LeafNodeType& leaf) { markLeaf(leaf, threshold); },
            [&](const openvdb::CoordBBox& b, float v) {
                if (v > threshold) markVoxels(b);
            });
    }

private:
    /// The bricks b0..b1 (per axis) that read some voxel of `voxels` (in the box).
    void brickRange(const openvdb::CoordBBox& voxels, int* b0, int* b1) const
    {
        for (int a = 0; a < 3; ++a) {
            const int l0 = voxels.min()[a] - mBox.min()[a], l1 = voxels.max()[a] - mBox.min()[a]; // ≥ 0
            b0[a] = std::max(0, (l0 + kBrick - 1) / kBrick - 1);
            b1[a] = std::min(mCount[a] - 1, l1 / kBrick);
        }
    }

    void set(int a, int b, int c)
    {
        const std::size_t i = std::size_t(a) + std::size_t(mCount[0]) * (std::size_t(b) + std::size_t(mCount[1]) * std::size_t(c));
        std::atomic_ref<std::uint8_t>(mActive[i]).store(1, std::memory_order_relaxed);
    }

    /// Mark the bricks that read a voxel of `leaf` above `threshold`: a bit per voxel above it
    /// (z bits per (x, y) column), then, for each of the ≤ 3³ bricks over the leaf, whether any
    /// column in its range has a bit in its z range. Thread-safe.
    template<typename LeafT>
    void markLeaf(const LeafT& leaf, float threshold)
    {
        openvdb::CoordBBox lb = leaf.getNodeBoundingBox();
        const openvdb::Coord o = lb.min();
        lb.intersect(mBox);
        if (lb.empty()) return;
        std::uint8_t column[8][8] = {};
        bool any = false;
        const float* v = leaf.buffer().data();
        for (int i = 0; i < 512; ++i)
            if (v[i] > threshold) {
                column[i >> 6][(i >> 3) & 7] |= std::uint8_t(1u << (i & 7));
                any = true;
            }
        if (!any) return;
        int b0[3], b1[3];
        brickRange(lb, b0, b1);
        int lo[3], hi[3];
        for (int c = b0[2]; c <= b1[2]; ++c)
            for (int b = b0[1]; b <= b1[1]; ++b)
                for (int a = b0[0]; a <= b1[0]; ++a) {
                    const int brick[3] = {a, b, c};
                    for (int ax = 0; ax < 3; ++ax) { // the brick's voxels in the leaf, leaf-local
                        lo[ax] = std::max(lb.min()[ax], mBox.min()[ax] + kBrick * brick[ax]) - o[ax];
                        hi[ax] = std::min(lb.max()[ax], mBox.min()[ax] + kBrick * brick[ax] + kBrick) - o[ax];
                    }
                    if (lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]) continue;
                    const std::uint8_t zmask = std::uint8_t((0xFFu >> (7 - hi[2] + lo[2])) << lo[2]);
                    bool hit = false;
                    for (int x = lo[0]; x <= hi[0] && !hit; ++x)
                        for (int y = lo[1]; y <= hi[1] && !hit; ++y) hit = (column[x][y] & zmask) != 0;
                    if (hit) set(a, b, c);
                }
    }

    /// Mark the bricks that read some voxel of `voxels` (index space). Thread-safe.
    void markVoxels(openvdb::CoordBBox voxels)
    {
        voxels.intersect(mBox);
        if (voxels.empty()) return;
        int b0[3], b1[3];
        brickRange(voxels, b0, b1);
        for (int c = b0[2]; c <= b1[2]; ++c)
            for (int b = b0[1]; b <= b1[1]; ++b)
                for (int a = b0[0]; a <= b1[0]; ++a) set(a, b, c);
    }

    openvdb::CoordBBox mBox; ///< the voxels there are (local 0 = its min)
    int mCount[3] = {0, 0, 0};
    std::vector<std::uint8_t> mActive;
};

} // namespace

struct HaloRaycaster::Impl
{
    RenderSettings settings;
    openvdb::math::Transform::Ptr xform;
    openvdb::Mat4d worldToIndex;
    double voxelLength = 1.0;
    openvdb::BBoxd worldBox;
    openvdb::Vec3d origin;     ///< index coordinates of local (0, 0, 0)
    int nx = 0, ny = 0, nz = 0; ///< dims of the box of voxels samples read
    openvdb::Vec3d extent;     ///< local sample box [0, extent]
    /// The grids on the density grid's voxels: the caller's own (shared, not copied) when the
    /// transforms are equal, as in a bake; else resampled (sparse). Null when not used.
    openvdb::FloatGrid::ConstPtr density, halo, scalar;
    openvdb::Vec3SGrid::ConstPtr color, tangent; ///< tangent: the tangent or flow grid (any length)
    std::vector<openvdb::Vec3s> lut; ///< with a colormap: colour by scalar, 1024 entries
    /// Where samples read the grids: their leaves over the blocks of the box.
    detail::LeafLayout layout;
    int layoutOffset[3] = {0, 0, 0}; ///< local (0, 0, 0) relative to layout.min()
    detail::LeafTable<float> densityLeaves, haloLeaves, scalarLeaves;
    /// Density and halo, read by every sample, as dense arrays over the box (x fastest) when the
    /// grids are dense; else samples read them through the tables.
    std::vector<float> denseDensity, denseHalo;
    bool dense = false;
    detail::LeafTable<openvdb::Vec3s> colorLeaves, tangentLeaves;
    BrickTable bricks;
    bool useHalo = false;
    bool haveTangent = false; ///< a tangent or flow grid was given
    bool colored = false;     ///< colour from `color` or the colormap over `scalar`
    bool lit = false;         ///< lighting enabled and a tangent

    // Construction, in this order.
    openvdb::CoordBBox setGeometry(const RenderVolume& vol, const openvdb::CoordBBox& active);
    void load(const RenderVolume& vol, const openvdb::CoordBBox& dbox, const openvdb::Coord& activeDim,
              Progress& progress);
    double autoDensityScale(const openvdb::CoordBBox& dbox, const openvdb::Coord& activeDim) const;
    void buildBrickTable(const openvdb::CoordBBox& dbox);
    void buildLeafTables(const openvdb::CoordBBox& dbox);

    // Rendering.
    void renderTile(const Camera& cam, Image& img, int x0, int y0, int x1, int y1, RenderStats& st) const;
    void renderPixel(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st,
                     const openvdb::Vec3d& light, bool headlight) const;
    template<bool Lit, bool Halo, bool Colored>
    void march(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st,
               const openvdb::Vec3d& light, bool headlight) const;
    template<bool Lit, bool Halo, bool Colored>
    class Marcher;
    /// The samples of a ray at parameters t0 + (k + ½)·dt, k in [0, kEnd).
    struct Samples;
    template<class M>
    [[gnu::always_inline]] inline void marchBricks(M& marcher, const Samples& samples, const openvdb::Vec3d& q0,
                                                   const openvdb::Vec3d& qd, RenderStats& st) const;
};

HaloRaycaster::HaloRaycaster(const RenderVolume& vol, const RenderSettings& settings, Progress& progress)
    : mImpl(std::make_unique<Impl>())
{
    settings.validate();
    checkVolume(vol, settings);
    Impl& m = *mImpl;
    m.settings = settings;
    m.xform = vol.density->transform().copy();
    const openvdb::CoordBBox active = activeBox(vol, settings, *m.xform);
    const openvdb::CoordBBox dbox = m.setGeometry(vol, active);
    {
        const ThreadLimit threadLimit(settings.threads);
        m.load(vol, dbox, active.dim(), progress);
        m.buildBrickTable(dbox);
        m.buildLeafTables(dbox);
    }
}

/// The transforms, the world box of `active` and the box of voxels that samples read; returns
/// that box. @throw InputError if it exceeds 2^31 voxels.
openvdb::CoordBBox HaloRaycaster::Impl::setGeometry(const RenderVolume& vol, const openvdb::CoordBBox& active)
{
    worldToIndex = xform->baseMap()->getAffineMap()->getMat4().inverse();
    const openvdb::Vec3d vs = xform->voxelSize();
    voxelLength = std::min({vs[0], vs[1], vs[2]});
    const openvdb::BBoxd ib(active.min().asVec3d() - openvdb::Vec3d(0.5), active.max().asVec3d() + openvdb::Vec3d(0.5));
    worldBox = xform->indexToWorld(ib);

    // Voxels [min − 1, max + 2]: samples lie in [min − 1, max + 1] (where trilinear support
    // ends), and the +1 neighbour of the last one must exist.
    const openvdb::CoordBBox dbox(active.min() - openvdb::Coord(1), active.max() + openvdb::Coord(2));
    const openvdb::Coord dim = dbox.dim();
    const double count = double(dim[0]) * double(dim[1]) * double(dim[2]);
    if (count > double(std::numeric_limits<int>::max()))
        throw InputError("the active bounding box of '" + vol.density->getName() + "' (" + std::to_string(dim[0]) + "x" +
                         std::to_string(dim[1]) + "x" + std::to_string(dim[2]) +
                         " voxels) is too large for the reference raycaster (at most 2^31 voxels)");
    nx = dim[0];
    ny = dim[1];
    nz = dim[2];
    origin = dbox.min().asVec3d();
    extent = openvdb::Vec3d(dim[0] - 2, dim[1] - 2, dim[2] - 2);
    return dbox;
}

/// Take the grids on the density grid's voxels (resampling those with another transform; one
/// progress unit per grid) and resolve an automatic density scale.
void HaloRaycaster::Impl::load(const RenderVolume& vol, const openvdb::CoordBBox& dbox, const openvdb::Coord& activeDim,
                               Progress& progress)
{
    int stages = 1 + (vol.halo && settings.halos) + (vol.color || settings.colormap) + (vol.tangent || vol.flow);
    progress.begin("load", std::uint64_t(stages));
    density = vol.density;
    if (settings.densityScale == 0.0)
        settings.densityScale = vol.halo ? kAutoLineScale : autoDensityScale(dbox, activeDim); // a line bake: each line nearly opaque
    progress.advance(1);
    detail::checkCancel(progress);
    if (vol.halo && settings.halos) {
        halo = onVoxelsOf<openvdb::FloatGrid>(vol.halo, *xform, dbox);
        useHalo = true;
        progress.advance(1);
    }
    detail::checkCancel(progress);
    if (settings.colormap || vol.color) {
        if (settings.colormap) {
            scalar = onVoxelsOf<openvdb::FloatGrid>(vol.scalar, *xform, dbox);
            lut = colormapTable(*settings.colormap);
        } else {
            color = onVoxelsOf<openvdb::Vec3SGrid>(vol.color, *xform, dbox);
        }
        colored = true;
        progress.advance(1);
    }
    detail::checkCancel(progress);
    haveTangent = vol.tangent || vol.flow;
    lit = haveTangent && settings.lighting.enabled;
    if (lit) { // unlit: not needed
        tangent = onVoxelsOf<openvdb::Vec3SGrid>(vol.tangent ? vol.tangent : vol.flow, *xform, dbox);
        progress.advance(1);
    }
    progress.end();
}

/// The mean windowed density over the box times the mean box depth (voxels) gives the optical
/// depth of an average ray; the scale makes it kAutoDepth. The same value for any thread count.
double HaloRaycaster::Impl::autoDensityScale(const openvdb::CoordBBox& dbox, const openvdb::Coord& activeDim) const
{
    const double lo = settings.densityLow, inv = 1.0 / (settings.densityHigh - settings.densityLow);
    const double mean = windowedSum(density->tree(), dbox, lo, inv) / double(dbox.volume());
    const double depth = (activeDim[0] + activeDim[1] + activeDim[2]) / 3.0;
    const double k = mean > 0.0 ? kAutoDepth / (mean * depth) : 1.0;
    return std::clamp(k, 1e-3, 8.0);
}

/// Brick occupancy: a brick can contribute if some voxel it reads is above the density window
/// or, with halos, above the halo threshold (a halo exit must still be seen).
void HaloRaycaster::Impl::buildBrickTable(const openvdb::CoordBBox& dbox)
{
    bricks = BrickTable(dbox, extent);
    bricks.mark(density->tree(), float(settings.densityLow));
    if (useHalo) bricks.mark(halo->tree(), float(settings.haloThreshold));
}

/// The tables of the grids' leaves that samples read.
void HaloRaycaster::Impl::buildLeafTables(const openvdb::CoordBBox& dbox)
{
    layout = detail::LeafLayout(dbox);
    for (int a = 0; a < 3; ++a) layoutOffset[a] = dbox.min()[a] - layout.min()[a];
    densityLeaves = detail::LeafTable<float>(density->tree(), layout);
    if (halo) haloLeaves = detail::LeafTable<float>(halo->tree(), layout);
    // Density and halo, which every sample reads, as dense arrays over the box when their leaves
    // fill at least half of it (a noise bake: the copy is at most twice the leaves, and a dense
    // index is the cheapest read: the table's measured 15-25 % more raymarch time there). Line
    // bakes, whose leaves fill a fraction of the box, read through the tables.
    dense = densityLeaves.leafBlocks() * 2 >= layout.blockCount();
    if (dense) {
        const std::size_t n = std::size_t(nx) * std::size_t(ny) * std::size_t(nz);
        auto copy = [&](const openvdb::FloatGrid& g, std::vector<float>& out) {
            out.assign(n, 0.0f);
            openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> d(dbox, out.data());
            openvdb::tools::copyToDense(g, d);
        };
        copy(*density, denseDensity);
        if (halo) copy(*halo, denseHalo);
    }
    if (scalar) scalarLeaves = detail::LeafTable<float>(scalar->tree(), layout);
    if (color) colorLeaves = detail::LeafTable<openvdb::Vec3s>(color->tree(), layout);
    if (tangent) tangentLeaves = detail::LeafTable<openvdb::Vec3s>(tangent->tree(), layout);
}

HaloRaycaster::~HaloRaycaster() = default;

const openvdb::BBoxd& HaloRaycaster::worldBBox() const { return mImpl->worldBox; }
bool HaloRaycaster::hasHalo() const { return mImpl->useHalo; }
bool HaloRaycaster::hasColor() const { return mImpl->colored; }
bool HaloRaycaster::hasTangent() const { return mImpl->haveTangent; }
bool HaloRaycaster::denseCopies() const { return mImpl->dense; }
const RenderSettings& HaloRaycaster::settings() const { return mImpl->settings; }

void HaloRaycaster::Impl::renderPixel(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st,
                                      const openvdb::Vec3d& lightDir, bool headlight) const
{
    // Dispatch once per ray to a marcher without per-sample branches on the configuration.
    const int key = (lit ? 4 : 0) | (useHalo ? 2 : 0) | (colored ? 1 : 0);
    switch (key) {
    case 0: return march<false, false, false>(ray, px, st, lightDir, headlight);
    case 1: return march<false, false, true>(ray, px, st, lightDir, headlight);
    case 2: return march<false, true, false>(ray, px, st, lightDir, headlight);
    case 3: return march<false, true, true>(ray, px, st, lightDir, headlight);
    case 4: return march<true, false, false>(ray, px, st, lightDir, headlight);
    case 5: return march<true, false, true>(ray, px, st, lightDir, headlight);
    case 6: return march<true, true, false>(ray, px, st, lightDir, headlight);
    default: return march<true, true, true>(ray, px, st, lightDir, headlight);
    }
}

namespace {

/// x^n for the specular exponent: by squaring when n is a small whole number (the usual case).
inline float specPow(float x, float n, int ni)
{
    if (ni < 0) return std::pow(x, n);
    float r = 1.0f, b = x;
    for (int e = ni; e; e >>= 1) {
        if (e & 1) r *= b;
        b *= b;
    }
    return r;
}

/// A 3D DDA over the 8³ bricks a ray q(t) = q0 + t·qd (local index space) crosses (Amanatides &
/// Woo), from the brick of q(t0).
class BrickWalk
{
public:
    [[gnu::always_inline]] BrickWalk(const openvdb::Vec3d& q0, const openvdb::Vec3d& qd, double t0, int bx, int by,
                                     int bz)
        : mCount{bx, by, bz}
    {
        const openvdb::Vec3d qs = q0 + qd * t0;
        for (int a = 0; a < 3; ++a) {
            mCell[a] = std::clamp(int(std::floor(qs[a] / kBrick)), 0, mCount[a] - 1);
            if (qd[a] > 1e-15) {
                mStep[a] = 1;
                mNext[a] = ((mCell[a] + 1) * double(kBrick) - q0[a]) / qd[a];
                mDelta[a] = kBrick / qd[a];
            } else if (qd[a] < -1e-15) {
                mStep[a] = -1;
                mNext[a] = (mCell[a] * double(kBrick) - q0[a]) / qd[a];
                mDelta[a] = -kBrick / qd[a];
            } else {
                mStep[a] = 0;
                mNext[a] = mDelta[a] = std::numeric_limits<double>::infinity();
            }
        }
    }

    /// Where the ray leaves the current brick (at most `t1`).
    double exit(double t1) const { return std::min({mNext[0], mNext[1], mNext[2], t1}); }
    /// The current brick's index in the occupancy table (x fastest).
    std::size_t brick() const
    {
        return std::size_t(mCell[0]) +
               std::size_t(mCount[0]) * (std::size_t(mCell[1]) + std::size_t(mCount[1]) * std::size_t(mCell[2]));
    }
    /// Step into the next brick, whose entry parameter goes to `entry`; false when the ray leaves
    /// the grid of bricks.
    [[gnu::always_inline]] bool next(double& entry)
    {
        int a = 0;
        if (mNext[1] < mNext[a]) a = 1;
        if (mNext[2] < mNext[a]) a = 2;
        mCell[a] += mStep[a];
        if (mCell[a] < 0 || mCell[a] >= mCount[a]) return false;
        entry = mNext[a];
        mNext[a] += mDelta[a];
        return true;
    }

private:
    int mCount[3], mCell[3], mStep[3];
    double mNext[3], mDelta[3];
};

} // namespace

/// The samples of a ray at parameters t0 + (k + ½)·dt (world units along the ray), k in
/// [0, kEnd): those before t1.
struct HaloRaycaster::Impl::Samples
{
    double t0, t1, dt;
    std::int64_t kEnd;

    Samples(double first, double last, double spacing)
        : t0(first), t1(last), dt(spacing), kEnd(std::int64_t(std::ceil((last - first) / spacing - 0.5)))
    {
    }
    double t(std::int64_t k) const { return t0 + (double(k) + 0.5) * dt; }
    /// The first sample at or after parameter `t`.
    std::int64_t firstFrom(double t) const { return std::int64_t(std::ceil((t - t0) / dt - 0.5)); }
};

/// One ray marched front to back: the transfer function's constants, what the ray has gathered
/// (colour, transmittance, the halo it is in), and its samples one at a time. The configuration is
/// template arguments, so a sample does not branch on it.
template<bool Lit, bool Halo, bool Colored>
class HaloRaycaster::Impl::Marcher
{
public:
    /// `rayDir` is the ray's unit world direction; `lightDir` the unit direction towards the light.
    Marcher(const Impl& impl, const openvdb::Vec3d& q0, const openvdb::Vec3d& qd, const openvdb::Vec3d& rayDir,
            const openvdb::Vec3d& lightDir, bool headlight, RenderStats& stats)
        : mImpl(impl), mSettings(impl.settings), mQ0(q0), mQd(qd), mStats(stats),
          mTau(mSettings.densityScale * mSettings.step), mLo(float(mSettings.densityLow)),
          mInvWindow(float(1.0 / (mSettings.densityHigh - mSettings.densityLow))), mThreshold(float(mSettings.haloThreshold)),
          mView(-rayDir), mLight(headlight ? mView : openvdb::Vec3f(lightDir)),
          mAmbient(float(mSettings.lighting.ambient)), mDiffuse(float(mSettings.lighting.diffuse)),
          mSpecular(float(mSettings.lighting.specular)), mShininess(float(mSettings.lighting.shininess)),
          mShininessInt((mShininess == std::floor(mShininess) && mShininess <= 256.0f) ? int(mShininess) : -1),
          mLast{impl.nx - 2, impl.ny - 2, impl.nz - 2},
          mOffset{impl.layoutOffset[0], impl.layoutOffset[1], impl.layoutOffset[2]},
          mDense(impl.dense), mDenseDensity(impl.denseDensity.data()), mDenseHalo(impl.denseHalo.data()),
          mSy(std::size_t(impl.nx)), mSz(std::size_t(impl.nx) * std::size_t(impl.ny)),
          mDensityTable(impl.densityLeaves.blocks()), mHaloTable(Halo ? impl.haloLeaves.blocks() : nullptr)
    {
        // Loaded by the first emitting sample (mEmitCell starts on no cell); zeroed so that the
        // compiler can see they are never read unset.
        std::fill(std::begin(mCol), std::end(mCol), openvdb::Vec3s(0.0f));
        std::fill(std::begin(mUnit), std::end(mUnit), openvdb::Vec3s(0.0f));
    }

    /// Take the sample at parameter `t`; false once the ray is opaque (finished).
    [[gnu::always_inline]] bool sample(double t)
    {
        ++mSamples;
        float w[8];
        moveTo(mQ0 + mQd * t, w);
        if constexpr (Halo) trackHalo(w);
        float rho = 0.0f;
        for (int k = 0; k < 8; ++k) rho += w[k] * mD[k];
        if (!(rho > mLo)) return true;
        const float rw = std::min(1.0f, (rho - mLo) * mInvWindow);
        const double alpha = 1.0 - double(std::exp(-float(mTau) * rw));
        const double weight = mT * alpha * mSettings.brightness;
        if (weight > 1e-9) emit(weight, rho, w);
        mT *= 1.0 - alpha;
        return !(mT < mSettings.minTransmittance);
    }

    /// An empty brick was skipped: a halo the ray was in ends there.
    void leaveHalo()
    {
        if (mInHalo) haloExit();
    }

    /// The pixel: premultiplied RGB and alpha.
    void write(float* px) const
    {
        mStats.samples += mSamples;
        px[0] = float(mR);
        px[1] = float(mG);
        px[2] = float(mB);
        px[3] = float(1.0 - mT);
    }

private:
    /// The trilinear weights `w` of local point `q` over the 8 voxels around it, in
    /// LeafLayout::Cell's order, and those voxels' density and halo (from the dense arrays or the
    /// tables). Every sample looks its cell up: reusing the last sample's cell measured slower
    /// (the test mispredicts about half of the time at half-voxel steps).
    [[gnu::always_inline]] void moveTo(const openvdb::Vec3d& q, float* w)
    {
        int ix = detail::floorIndex(q[0]), iy = detail::floorIndex(q[1]), iz = detail::floorIndex(q[2]);
        ix = std::clamp(ix, 0, mLast[0]);
        iy = std::clamp(iy, 0, mLast[1]);
        iz = std::clamp(iz, 0, mLast[2]);
        const float fx = float(std::clamp(q[0] - ix, 0.0, 1.0));
        const float fy = float(std::clamp(q[1] - iy, 0.0, 1.0));
        const float fz = float(std::clamp(q[2] - iz, 0.0, 1.0));
        const float ws[8] = {(1 - fx) * (1 - fy) * (1 - fz), fx * (1 - fy) * (1 - fz), (1 - fx) * fy * (1 - fz),
                             fx * fy * (1 - fz),       (1 - fx) * (1 - fy) * fz, fx * (1 - fy) * fz,
                             (1 - fx) * fy * fz,       fx * fy * fz};
        for (int k = 0; k < 8; ++k) w[k] = ws[k];
        if (mDense) { // the same for the whole render: predicted
            const std::size_t i000 = std::size_t(ix) + mSy * std::size_t(iy) + mSz * std::size_t(iz);
            const std::size_t idx[8] = {i000,       i000 + 1,       i000 + mSy,       i000 + mSy + 1,
                                        i000 + mSz, i000 + mSz + 1, i000 + mSz + mSy, i000 + mSz + mSy + 1};
            for (int k = 0; k < 8; ++k) mD[k] = mDenseDensity[idx[k]];
            if constexpr (Halo)
                for (int k = 0; k < 8; ++k) mH[k] = mDenseHalo[idx[k]];
        }
        ix += mOffset[0];
        iy += mOffset[1];
        iz += mOffset[2];
        if (!mDense) {
            const detail::LeafLayout::Cell at = mImpl.layout.cell(ix, iy, iz);
            for (int k = 0; k < 8; ++k) mD[k] = mDensityTable[at.block[k]][at.offset[k]];
            if constexpr (Halo)
                for (int k = 0; k < 8; ++k) mH[k] = mHaloTable[at.block[k]][at.offset[k]];
        }
        if constexpr (Colored || Lit) { // the other grids are read only when the sample emits
            mCell[0] = ix;
            mCell[1] = iy;
            mCell[2] = iz;
        }
    }

    /// Enter, stay in or leave a halo by the halo value at the sample.
    [[gnu::always_inline]] void trackHalo(const float* w)
    {
        float h = 0.0f;
        for (int k = 0; k < 8; ++k) h += w[k] * mH[k];
        if (h > mThreshold) {
            if (!mInHalo) {
                mInHalo = true;
                mHaloMax = h;
            } else {
                mHaloMax = std::max(mHaloMax, h);
            }
        } else if (mInHalo) {
            haloExit();
        }
    }

    /// At a halo exit the opacity so far is raised by haloStrength × the halo's maximum.
    void haloExit()
    {
        mInHalo = false;
        const double A = std::min(1.0, (1.0 - mT) + mSettings.haloStrength * double(mHaloMax));
        mT = 1.0 - A;
    }

    /// Add the light of a sample of (positive) `weight`, density `rho` and trilinear weights `w`:
    /// colour, lit when Lit.
    [[gnu::always_inline]] void emit(double weight, float rho, const float* w)
    {
        if constexpr (Colored || Lit) {
            // The corners' colours and unit tangents, read once per cell (consecutive samples
            // often share one).
            if (mCell[0] != mEmitCell[0] || mCell[1] != mEmitCell[1] || mCell[2] != mEmitCell[2]) {
                for (int a = 0; a < 3; ++a) mEmitCell[a] = mCell[a];
                const detail::LeafLayout::Cell at = mImpl.layout.cell(mCell[0], mCell[1], mCell[2]);
                if constexpr (Colored) colors(at, mCol);
                if constexpr (Lit) unitTangents(at, mUnit);
            }
        }
        openvdb::Vec3f c(1.0f);
        if constexpr (Colored) {
            // Density-weighted: colour belongs to the lines, so voxels without density
            // (outside the colour grid's active region: black) do not darken line edges.
            openvdb::Vec3f cs(0.0f);
            for (int k = 0; k < 8; ++k) cs += mCol[k] * (w[k] * mD[k]);
            c = cs / rho;
        }
        float spec = 0.0f;
        if constexpr (Lit) {
            // The trilinear tangent (not renormalised) of the corners' unit tangents.
            openvdb::Vec3f ts(0.0f);
            for (int k = 0; k < 8; ++k) ts += mUnit[k] * w[k];
            c *= lineLight(ts, spec);
        }
        mR += weight * (c[0] + spec);
        mG += weight * (c[1] + spec);
        mB += weight * (c[2] + spec);
    }

    /// The corners' colours: the colormap's over `scalar`, else `color`.
    [[gnu::always_inline]] void colors(const detail::LeafLayout::Cell& at, openvdb::Vec3s* col) const
    {
        if (!mImpl.lut.empty()) {
            float s[8];
            mImpl.scalarLeaves.read(at, s);
            for (int k = 0; k < 8; ++k)
                col[k] = mImpl.lut[std::size_t(std::lround(std::clamp(s[k], 0.0f, 1.0f) * 1023.0f))];
        } else {
            mImpl.colorLeaves.read(at, col);
        }
    }

    /// The corners' unit tangents (0 where the tangent grid's vector is 0).
    [[gnu::always_inline]] void unitTangents(const detail::LeafLayout::Cell& at, openvdb::Vec3s* unit) const
    {
        openvdb::Vec3s t[8];
        mImpl.tangentLeaves.read(at, t);
        for (int k = 0; k < 8; ++k) {
            const float len = t[k].length();
            unit[k] = len > 1e-20f ? t[k] / len : openvdb::Vec3s(0.0f);
        }
    }

    /// Zöckler et al.: the diffuse factor √(1−(L·T)²) (with ambient) of a line of tangent `ts`
    /// (any length), and its specular term into `spec`, from V·R = √(1−(L·T)²)·√(1−(V·T)²) − (L·T)(V·T).
    [[gnu::always_inline]] float lineLight(const openvdb::Vec3f& ts, float& spec) const
    {
        const float len2 = ts.lengthSqr();
        if (!(len2 > 1e-12f)) return mAmbient + mDiffuse;
        const float inv = 1.0f / std::sqrt(len2);
        const float lt = mLight.dot(ts) * inv, vt = mView.dot(ts) * inv;
        // √(1 − (L·T)²) = |L × T| for unit vectors, accurate near parallel.
        const float sl = mLight.cross(ts).length() * inv;
        const float sv = mView.cross(ts).length() * inv;
        const float vr = sl * sv - lt * vt;
        spec = vr > 0.0f ? mSpecular * specPow(vr, mShininess, mShininessInt) : 0.0f;
        return mAmbient + mDiffuse * sl;
    }

    const Impl& mImpl;
    const RenderSettings& mSettings;
    const openvdb::Vec3d mQ0, mQd; ///< the ray in local index space: q(t) = q0 + t·qd
    RenderStats& mStats;
    const double mTau; ///< optical depth per step at windowed density 1
    const float mLo, mInvWindow, mThreshold;
    const openvdb::Vec3f mView, mLight; ///< unit directions towards the eye and the light
    const float mAmbient, mDiffuse, mSpecular, mShininess;
    const int mShininessInt;
    double mT = 1.0, mR = 0.0, mG = 0.0, mB = 0.0; ///< transmittance and gathered light
    bool mInHalo = false;
    float mHaloMax = 0.0f;
    /// With colour or lighting: the sample's cell (its lowest voxel) in the leaf layout.
    int mCell[3] = {0, 0, 0};
    /// The cell whose colours and unit tangents mCol and mUnit hold.
    int mEmitCell[3] = {std::numeric_limits<int>::min(), 0, 0};
    openvdb::Vec3s mCol[8], mUnit[8];
    float mD[8] = {}, mH[8] = {}; ///< the sample's cell's density and halo
    std::uint64_t mSamples = 0;
    const int mLast[3];   ///< the highest cell per axis (local)
    const int mOffset[3]; ///< local (0, 0, 0) in the leaf layout
    const bool mDense;
    const float* const mDenseDensity;
    const float* const mDenseHalo;
    const std::size_t mSy, mSz; ///< the dense arrays' voxel strides of y and z
    const float* const* const mDensityTable;
    const float* const* const mHaloTable;
};

template<bool Lit, bool Halo, bool Colored>
void HaloRaycaster::Impl::march(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st,
                                const openvdb::Vec3d& lightDir, bool headlight) const
{
    px[0] = px[1] = px[2] = px[3] = 0.0f;
    ++st.rays;
    // Ray in local index coordinates: q(t) = q0 + t·qd, t in world units.
    const openvdb::Vec3d q0 = worldToIndex.transform(ray.eye()) - origin;
    const openvdb::Vec3d qd = worldToIndex.transform3x3(ray.dir());
    double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) { // clip to the sample box [0, extent]
        if (std::abs(qd[a]) < 1e-15) {
            if (q0[a] < 0.0 || q0[a] > extent[a]) return;
            continue;
        }
        double ta = (0.0 - q0[a]) / qd[a], tb = (extent[a] - q0[a]) / qd[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) return;

    const Samples samples(t0, t1, settings.step * voxelLength);
    Marcher<Lit, Halo, Colored> marcher(*this, q0, qd, ray.dir(), lightDir, headlight, st);
    if (settings.emptySpaceSkipping) {
        marchBricks(marcher, samples, q0, qd, st);
    } else {
        for (std::int64_t k = 0; k < samples.kEnd; ++k)
            if (samples.t(k) < t1 && !marcher.sample(samples.t(k))) break;
    }
    marcher.write(px);
}

/// March the samples that lie in bricks that can contribute, skipping the others.
template<class M>
void HaloRaycaster::Impl::marchBricks(M& marcher, const Samples& samples, const openvdb::Vec3d& q0,
                                      const openvdb::Vec3d& qd, RenderStats& st) const
{
    BrickWalk walk(q0, qd, samples.t0, bricks.count(0), bricks.count(1), bricks.count(2));
    std::int64_t k = 0;
    double entry = samples.t0;
    bool prevActive = true;
    while (true) {
        const double tExit = walk.exit(samples.t1);
        const bool on = bricks.active(walk.brick());
        if (on) {
            if (!prevActive) k = std::max(k, samples.firstFrom(entry));
            for (; k < samples.kEnd && samples.t(k) < tExit; ++k)
                if (!marcher.sample(samples.t(k))) return;
        } else {
            ++st.skippedBricks;
            marcher.leaveHalo();
        }
        prevActive = on;
        if (tExit >= samples.t1 || k >= samples.kEnd) return;
        if (!walk.next(entry)) return;
    }
}

void HaloRaycaster::Impl::renderTile(const Camera& cam, Image& img, int x0, int y0, int x1, int y1,
                                     RenderStats& st) const
{
    openvdb::Vec3d light = settings.lighting.direction;
    if (light.length() > 0.0) light.normalize();
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x)
            renderPixel(cam.ray(x + 0.5, y + 0.5), img.pixel(x, y), st, light, settings.lighting.headlight);
}

Image HaloRaycaster::render(const Camera& cam, Progress& progress, RenderStats* stats) const
{
    if (cam.width < 1 || cam.height < 1) throw InputError("camera image size must be at least 1x1");
    Image img(cam.width, cam.height);
    const int tx = (cam.width + kTile - 1) / kTile, ty = (cam.height + kTile - 1) / kTile;
    std::atomic<std::uint64_t> rays{0}, samples{0}, skipped{0};
    std::atomic<bool> cancelled{false};
    progress.begin("render", std::uint64_t(cam.width) * std::uint64_t(cam.height));
    {
        const ThreadLimit threadLimit(mImpl->settings.threads);
        tbb::parallel_for(tbb::blocked_range<int>(0, tx * ty, 1), [&](const tbb::blocked_range<int>& r) {
            for (int t = r.begin(); t != r.end(); ++t) {
                if (cancelled.load(std::memory_order_relaxed)) return;
                if (progress.wasInterrupted()) {
                    cancelled = true;
                    return;
                }
                const int x0 = (t % tx) * kTile, y0 = (t / tx) * kTile;
                const int x1 = std::min(x0 + kTile, cam.width), y1 = std::min(y0 + kTile, cam.height);
                RenderStats st;
                mImpl->renderTile(cam, img, x0, y0, x1, y1, st);
                rays += st.rays;
                samples += st.samples;
                skipped += st.skippedBricks;
                progress.advance(std::uint64_t(x1 - x0) * std::uint64_t(y1 - y0));
            }
        }, tbb::simple_partitioner());
    }
    if (cancelled) throw Cancelled();
    progress.end();
    if (stats) {
        stats->rays = rays;
        stats->samples = samples;
        stats->skippedBricks = skipped;
    }
    return img;
}

} // namespace lic

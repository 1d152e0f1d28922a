#include "lic/render/Raycaster.h"

#include "lic/util/Error.h"
#include "lic/util/Parallel.h"

#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Interpolation.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
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

/// Copy (same transform) or resample (trilinear, world space) `grid` onto the voxels of `bbox`
/// in `target`'s index space, x fastest.
template<typename GridT>
void fillDense(const GridT& grid, const openvdb::math::Transform& target, const openvdb::CoordBBox& bbox,
               typename GridT::ValueType* out)
{
    using ValueT = typename GridT::ValueType;
    if (grid.transform() == target) {
        openvdb::tools::Dense<ValueT, openvdb::tools::LayoutXYZ> dense(bbox, out);
        openvdb::tools::copyToDense(grid, dense);
        return;
    }
    const openvdb::Coord dim = bbox.dim();
    tbb::parallel_for(tbb::blocked_range<int>(0, dim[2]), [&](const tbb::blocked_range<int>& r) {
        auto acc = grid.getConstAccessor();
        openvdb::tools::GridSampler<decltype(acc), openvdb::tools::BoxSampler> sampler(acc, grid.transform());
        for (int k = r.begin(); k != r.end(); ++k)
            for (int j = 0; j < dim[1]; ++j)
                for (int i = 0; i < dim[0]; ++i) {
                    const openvdb::Vec3d w =
                        target.indexToWorld(openvdb::Vec3d(bbox.min()[0] + i, bbox.min()[1] + j, bbox.min()[2] + k));
                    out[std::size_t(i) + std::size_t(dim[0]) * (std::size_t(j) + std::size_t(dim[1]) * std::size_t(k))] =
                        sampler.wsSample(w);
                }
    });
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

/// `f(i)` for every i in [0, n), in parallel.
template<typename F>
void forEachVoxel(std::size_t n, const F& f)
{
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 16), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

} // namespace

struct HaloRaycaster::Impl
{
    RenderSettings settings;
    openvdb::math::Transform::Ptr xform;
    openvdb::Mat4d worldToIndex;
    double voxelLength = 1.0;
    openvdb::BBoxd worldBox;
    openvdb::Vec3d origin;     ///< index coordinates of local (0, 0, 0)
    int nx = 0, ny = 0, nz = 0; ///< dense dims
    openvdb::Vec3d extent;     ///< local sample box [0, extent]
    std::vector<float> density, halo;
    std::vector<openvdb::Vec3s> color, tangent;
    /// With a tangent: density and tangent packed per voxel (ρ, tx, ty, tz), one cache line per
    /// 4 voxels; `density` and `tangent` are then released.
    std::vector<openvdb::Vec4f> packed;
    int bx = 0, by = 0, bz = 0;
    std::vector<std::uint8_t> brickActive;
    bool useHalo = false;
    bool haveTangent = false; ///< a tangent or flow grid was given

    // Construction, in this order.
    openvdb::CoordBBox setGeometry(const RenderVolume& vol, const openvdb::CoordBBox& active);
    void load(const RenderVolume& vol, const openvdb::CoordBBox& dbox, const openvdb::Coord& activeDim,
              Progress& progress);
    double autoDensityScale(const openvdb::Coord& activeDim) const;
    void loadColor(const RenderVolume& vol, const openvdb::CoordBBox& dbox);
    void loadTangent(const RenderVolume& vol, const openvdb::CoordBBox& dbox);
    void buildBrickTable();
    void packDensityAndTangent();

    // Rendering.
    void renderTile(const Camera& cam, Image& img, int x0, int y0, int x1, int y1, RenderStats& st) const;
    void renderPixel(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st, const openvdb::Vec3d& light,
                     bool headlight) const;
    template<bool Lit, bool Halo, bool Colored>
    void march(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st, const openvdb::Vec3d& light,
               bool headlight) const;
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
        m.buildBrickTable();
        m.haveTangent = !m.tangent.empty();
        if (!m.settings.lighting.enabled) std::vector<openvdb::Vec3s>().swap(m.tangent); // unlit: not needed
        if (!m.tangent.empty()) m.packDensityAndTangent();
    }
}

/// The transforms, the world box of `active` and the dense arrays' box and dims; returns that box.
/// @throw InputError if it exceeds 2^31 voxels.
openvdb::CoordBBox HaloRaycaster::Impl::setGeometry(const RenderVolume& vol, const openvdb::CoordBBox& active)
{
    worldToIndex = xform->baseMap()->getAffineMap()->getMat4().inverse();
    const openvdb::Vec3d vs = xform->voxelSize();
    voxelLength = std::min({vs[0], vs[1], vs[2]});
    const openvdb::BBoxd ib(active.min().asVec3d() - openvdb::Vec3d(0.5), active.max().asVec3d() + openvdb::Vec3d(0.5));
    worldBox = xform->indexToWorld(ib);

    // Dense arrays over [min − 1, max + 2]: samples lie in [min − 1, max + 1] (where trilinear
    // support ends), and the +1 neighbour of the last one must exist.
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

/// Fill the dense arrays over `dbox` (one progress unit per grid) and resolve an automatic
/// density scale.
void HaloRaycaster::Impl::load(const RenderVolume& vol, const openvdb::CoordBBox& dbox, const openvdb::Coord& activeDim,
                               Progress& progress)
{
    const std::size_t n = std::size_t(nx) * std::size_t(ny) * std::size_t(nz);
    int stages = 1 + (vol.halo && settings.halos) + (vol.color || settings.colormap) + (vol.tangent || vol.flow);
    progress.begin("load", std::uint64_t(stages));
    density.assign(n, 0.0f);
    fillDense(*vol.density, *xform, dbox, density.data());
    if (settings.densityScale == 0.0)
        settings.densityScale = vol.halo ? kAutoLineScale : autoDensityScale(activeDim); // a line bake: each line nearly opaque
    progress.advance(1);
    detail::checkCancel(progress);
    if (vol.halo && settings.halos) {
        halo.assign(n, 0.0f);
        fillDense(*vol.halo, *xform, dbox, halo.data());
        useHalo = true;
        progress.advance(1);
    }
    detail::checkCancel(progress);
    if (settings.colormap || vol.color) {
        loadColor(vol, dbox);
        progress.advance(1);
    }
    detail::checkCancel(progress);
    if (vol.tangent || vol.flow) {
        loadTangent(vol, dbox);
        progress.advance(1);
    }
    progress.end();
}

/// The mean windowed density over the box times the mean box depth (voxels) gives the optical
/// depth of an average ray; the scale makes it kAutoDepth. Summed per z slice, then slices in
/// order: the same value for any thread count.
double HaloRaycaster::Impl::autoDensityScale(const openvdb::Coord& activeDim) const
{
    std::vector<double> slice(std::size_t(nz), 0.0);
    const double lo = settings.densityLow, inv = 1.0 / (settings.densityHigh - settings.densityLow);
    const std::size_t per = std::size_t(nx) * std::size_t(ny);
    tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& r) {
        for (int k = r.begin(); k != r.end(); ++k) {
            double acc = 0.0;
            for (std::size_t i = std::size_t(k) * per, e = i + per; i < e; ++i)
                acc += std::clamp((double(density[i]) - lo) * inv, 0.0, 1.0);
            slice[std::size_t(k)] = acc;
        }
    });
    double sum = 0.0;
    for (double v : slice) sum += v;
    const double mean = sum / double(density.size());
    const double depth = (activeDim[0] + activeDim[1] + activeDim[2]) / 3.0;
    const double k = mean > 0.0 ? kAutoDepth / (mean * depth) : 1.0;
    return std::clamp(k, 1e-3, 8.0);
}

/// `color`: the colormap over the scalar grid (a 1024-entry table), else the colour grid.
void HaloRaycaster::Impl::loadColor(const RenderVolume& vol, const openvdb::CoordBBox& dbox)
{
    const std::size_t n = density.size();
    if (!settings.colormap) {
        color.assign(n, openvdb::Vec3s(0.0f));
        fillDense(*vol.color, *xform, dbox, color.data());
        return;
    }
    std::vector<float> s(n, 0.0f);
    fillDense(*vol.scalar, *xform, dbox, s.data());
    const std::vector<openvdb::Vec3s> lut = colormapTable(*settings.colormap);
    color.resize(n);
    forEachVoxel(n, [&](std::size_t i) {
        const float v = std::clamp(s[i], 0.0f, 1.0f);
        color[i] = lut[std::size_t(std::lround(v * 1023.0f))];
    });
}

/// `tangent`: the unit tangent grid's or flow field's direction (0 where it has none).
void HaloRaycaster::Impl::loadTangent(const RenderVolume& vol, const openvdb::CoordBBox& dbox)
{
    tangent.assign(density.size(), openvdb::Vec3s(0.0f));
    fillDense(vol.tangent ? *vol.tangent : *vol.flow, *xform, dbox, tangent.data());
    forEachVoxel(tangent.size(), [&](std::size_t i) {
        const float len = tangent[i].length();
        tangent[i] = len > 1e-20f ? tangent[i] / len : openvdb::Vec3s(0.0f);
    });
}

/// Brick occupancy: brick b covers local samples [8b, 8b + 8) and reads voxels [8b, 8b + 8]. It
/// can contribute if some voxel there is above the density window or, with halos, above the halo
/// threshold (a halo exit must still be seen).
void HaloRaycaster::Impl::buildBrickTable()
{
    bx = int(std::floor(extent[0] / kBrick)) + 1;
    by = int(std::floor(extent[1] / kBrick)) + 1;
    bz = int(std::floor(extent[2] / kBrick)) + 1;
    brickActive.assign(std::size_t(bx) * std::size_t(by) * std::size_t(bz), 0);
    const float lo = float(settings.densityLow), thr = float(settings.haloThreshold);
    auto contributes = [&](int a, int b, int c) {
        for (int k = c * kBrick; k <= std::min(c * kBrick + kBrick, nz - 1); ++k)
            for (int j = b * kBrick; j <= std::min(b * kBrick + kBrick, ny - 1); ++j) {
                const std::size_t row = std::size_t(nx) * (std::size_t(j) + std::size_t(ny) * std::size_t(k));
                for (int i = a * kBrick; i <= std::min(a * kBrick + kBrick, nx - 1); ++i)
                    if (density[row + std::size_t(i)] > lo || (useHalo && halo[row + std::size_t(i)] > thr)) return true;
            }
        return false;
    };
    tbb::parallel_for(tbb::blocked_range<int>(0, bz), [&](const tbb::blocked_range<int>& r) {
        for (int c = r.begin(); c != r.end(); ++c)
            for (int b = 0; b < by; ++b)
                for (int a = 0; a < bx; ++a)
                    brickActive[std::size_t(a) + std::size_t(bx) * (std::size_t(b) + std::size_t(by) * std::size_t(c))] =
                        contributes(a, b, c);
    });
}

/// Density and tangent into `packed`; both are released.
void HaloRaycaster::Impl::packDensityAndTangent()
{
    packed.resize(density.size());
    forEachVoxel(packed.size(), [&](std::size_t i) {
        packed[i] = openvdb::Vec4f(density[i], tangent[i][0], tangent[i][1], tangent[i][2]);
    });
    std::vector<float>().swap(density);
    std::vector<openvdb::Vec3s>().swap(tangent);
}

HaloRaycaster::~HaloRaycaster() = default;

const openvdb::BBoxd& HaloRaycaster::worldBBox() const { return mImpl->worldBox; }
bool HaloRaycaster::hasHalo() const { return mImpl->useHalo; }
bool HaloRaycaster::hasColor() const { return !mImpl->color.empty(); }
bool HaloRaycaster::hasTangent() const { return mImpl->haveTangent; }
const RenderSettings& HaloRaycaster::settings() const { return mImpl->settings; }

void HaloRaycaster::Impl::renderPixel(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st,
                                      const openvdb::Vec3d& lightDir, bool headlight) const
{
    const bool lit = settings.lighting.enabled && !packed.empty();
    const bool colored = !color.empty();
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
          mDensity(Lit ? nullptr : impl.density.data()), mPacked(Lit ? impl.packed.data() : nullptr),
          mSy(std::size_t(impl.nx)), mSz(std::size_t(impl.nx) * std::size_t(impl.ny))
    {
    }

    /// Take the sample at parameter `t`; false once the ray is opaque (finished).
    [[gnu::always_inline]] bool sample(double t)
    {
        ++mStats.samples;
        const Corners c = corners(mQ0 + mQd * t);
        if constexpr (Halo) trackHalo(c);
        float rho = 0.0f;
        openvdb::Vec4f dtan(0.0f);
        if constexpr (Lit) {
            for (int k = 0; k < 8; ++k) dtan += mPacked[c.idx[k]] * c.w[k];
            rho = dtan[0];
        } else {
            for (int k = 0; k < 8; ++k) rho += c.w[k] * mDensity[c.idx[k]];
        }
        if (!(rho > mLo)) return true;
        const float rw = std::min(1.0f, (rho - mLo) * mInvWindow);
        const double alpha = 1.0 - double(std::exp(-float(mTau) * rw));
        const double weight = mT * alpha * mSettings.brightness;
        if (weight > 1e-9) emit(weight, rho, c, dtan);
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
        px[0] = float(mR);
        px[1] = float(mG);
        px[2] = float(mB);
        px[3] = float(1.0 - mT);
    }

private:
    /// The 8 voxels around a local point and their trilinear weights.
    struct Corners
    {
        float w[8];
        std::size_t idx[8];
    };

    [[gnu::always_inline]] Corners corners(const openvdb::Vec3d& q) const
    {
        const double fx0 = std::floor(q[0]), fy0 = std::floor(q[1]), fz0 = std::floor(q[2]);
        int ix = int(fx0), iy = int(fy0), iz = int(fz0);
        ix = std::clamp(ix, 0, mImpl.nx - 2);
        iy = std::clamp(iy, 0, mImpl.ny - 2);
        iz = std::clamp(iz, 0, mImpl.nz - 2);
        const float fx = float(std::clamp(q[0] - ix, 0.0, 1.0));
        const float fy = float(std::clamp(q[1] - iy, 0.0, 1.0));
        const float fz = float(std::clamp(q[2] - iz, 0.0, 1.0));
        const std::size_t i000 = std::size_t(ix) + mSy * std::size_t(iy) + mSz * std::size_t(iz);
        return {{(1 - fx) * (1 - fy) * (1 - fz), fx * (1 - fy) * (1 - fz), (1 - fx) * fy * (1 - fz), fx * fy * (1 - fz),
                 (1 - fx) * (1 - fy) * fz, fx * (1 - fy) * fz, (1 - fx) * fy * fz, fx * fy * fz},
                {i000, i000 + 1, i000 + mSy, i000 + mSy + 1, i000 + mSz, i000 + mSz + 1, i000 + mSz + mSy,
                 i000 + mSz + mSy + 1}};
    }

    /// Enter, stay in or leave a halo by the halo value at the sample.
    [[gnu::always_inline]] void trackHalo(const Corners& c)
    {
        float h = 0.0f;
        for (int k = 0; k < 8; ++k) h += c.w[k] * mImpl.halo[c.idx[k]];
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

    /// Add the light of a sample of (positive) `weight`: colour, lit when Lit.
    [[gnu::always_inline]] void emit(double weight, float rho, const Corners& corner, const openvdb::Vec4f& dtan)
    {
        openvdb::Vec3f c(1.0f);
        if constexpr (Colored) {
            // Density-weighted: colour belongs to the lines, so voxels without density
            // (outside the colour grid's active region: black) do not darken line edges.
            openvdb::Vec3f cs(0.0f);
            for (int k = 0; k < 8; ++k) {
                const float dk = Lit ? mPacked[corner.idx[k]][0] : mDensity[corner.idx[k]];
                cs += mImpl.color[corner.idx[k]] * (corner.w[k] * dk);
            }
            c = cs / rho;
        }
        float spec = 0.0f;
        if constexpr (Lit) c *= lineLight(openvdb::Vec3f(dtan[1], dtan[2], dtan[3]), spec);
        mR += weight * (c[0] + spec);
        mG += weight * (c[1] + spec);
        mB += weight * (c[2] + spec);
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
    const float* const mDensity;
    const openvdb::Vec4f* const mPacked;
    const std::size_t mSy, mSz; ///< voxel strides of y and z
    double mT = 1.0, mR = 0.0, mG = 0.0, mB = 0.0; ///< transmittance and gathered light
    bool mInHalo = false;
    float mHaloMax = 0.0f;
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
    BrickWalk walk(q0, qd, samples.t0, bx, by, bz);
    std::int64_t k = 0;
    double entry = samples.t0;
    bool prevActive = true;
    while (true) {
        const double tExit = walk.exit(samples.t1);
        const bool on = brickActive[walk.brick()];
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

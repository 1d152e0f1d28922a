#include "lic/render/Raycaster.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"
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

namespace {

constexpr double kPi = 3.14159265358979323846;
double radians(double deg) { return deg * kPi / 180.0; }
double degrees(double rad) { return rad * 180.0 / kPi; }

/// sin and cos of an angle in degrees, exact at multiples of 90° (named views get exact axes).
double sinDeg(double deg)
{
    const double r = std::fmod(deg, 360.0);
    if (r == 0.0 || std::abs(r) == 180.0) return 0.0;
    if (r == 90.0 || r == -270.0) return 1.0;
    if (r == -90.0 || r == 270.0) return -1.0;
    return std::sin(radians(deg));
}
double cosDeg(double deg) { return sinDeg(deg + 90.0); }

std::string num(double v)
{
    std::ostringstream s;
    s << v;
    return s.str();
}

} // namespace

// ---- cameras --------------------------------------------------------------------------------

const char* toString(Projection p) { return p == Projection::Perspective ? "perspective" : "orthographic"; }

double Camera::fovX() const
{
    const double ty = std::tan(radians(fovY) * 0.5);
    return degrees(2.0 * std::atan(ty * double(width) / double(height)));
}

openvdb::math::Ray<double> Camera::ray(double x, double y) const
{
    const double u = 2.0 * x / double(width) - 1.0;  // −1 … 1, left → right
    const double v = 1.0 - 2.0 * y / double(height); // −1 … 1, bottom → top
    if (projection == Projection::Orthographic) {
        const openvdb::Vec3d o = position + right * (u * 0.5 * orthoWidth) + up * (v * 0.5 * orthoHeight);
        return openvdb::math::Ray<double>(o, forward);
    }
    const double ty = std::tan(radians(fovY) * 0.5);
    const double tx = ty * double(width) / double(height);
    openvdb::Vec3d d = forward + right * (u * tx) + up * (v * ty);
    d.normalize();
    return openvdb::math::Ray<double>(position, d);
}

namespace {
constexpr EnumName<View> kViewNames[] = {{View::Front, "front"}, {View::Back, "back"},   {View::Left, "left"},
                                         {View::Right, "right"}, {View::Top, "top"}, {View::Bottom, "bottom"}};
constexpr EnumName<StereoMode> kStereoNames[] = {{StereoMode::None, "none"},
                                                 {StereoMode::SideBySide, "sbs", "side by side"},
                                                 {StereoMode::Anaglyph, "anaglyph"},
                                                 {StereoMode::SideBySide, "side-by-side"},
                                                 {StereoMode::None, ""}};
} // namespace

View viewFromString(const std::string& s) { return valueOf<View>(kViewNames, s, "view"); }

const char* toString(View v) { return nameOf<View>(kViewNames, v); }

std::pair<double, double> viewAngles(View v)
{
    switch (v) {
    case View::Front: return {0.0, 0.0};
    case View::Back: return {180.0, 0.0};
    case View::Right: return {90.0, 0.0};
    case View::Left: return {-90.0, 0.0};
    case View::Top: return {0.0, 90.0};
    case View::Bottom: return {0.0, -90.0};
    }
    return {0.0, 0.0};
}

void CameraSettings::validate() const
{
    if (!std::isfinite(azimuth)) throw InputError("azimuth " + num(azimuth) + " is not a number of degrees");
    if (!(elevation >= -90.0 && elevation <= 90.0))
        throw InputError("elevation " + num(elevation) + " is out of range; expected degrees in [-90, 90]");
    if (distance && !(*distance > 0.0 && std::isfinite(*distance)))
        throw InputError("distance " + num(*distance) + " is out of range; expected world units > 0");
    if (!(fovY > 0.0 && fovY < 180.0))
        throw InputError("field of view " + num(fovY) + " is out of range; expected degrees in (0, 180)");
    if (orthoHeight && !(*orthoHeight > 0.0 && std::isfinite(*orthoHeight)))
        throw InputError("orthographic height " + num(*orthoHeight) + " is out of range; expected world units > 0");
    if (width < 1 || height < 1 || width > 32768 || height > 32768)
        throw InputError("image size " + std::to_string(width) + "x" + std::to_string(height) +
                         " is out of range; expected 1 to 32768 pixels each way");
    if (!(margin >= 0.0 && margin < 0.5)) throw InputError("margin " + num(margin) + " is out of range; expected [0, 0.5)");
}

Camera makeCamera(const CameraSettings& s, const openvdb::BBoxd& box)
{
    s.validate();
    if (!box.isSorted() || !std::isfinite(box.min()[0]) || !std::isfinite(box.max()[0]))
        throw InputError("cannot frame an empty bounding box");
    Camera cam;
    cam.projection = s.orthographic ? Projection::Orthographic : Projection::Perspective;
    cam.width = s.width;
    cam.height = s.height;
    cam.fovY = s.fovY;
    cam.azimuth = s.azimuth;
    cam.elevation = s.elevation;
    cam.target = box.getCenter();

    const double sa = sinDeg(s.azimuth), ca = cosDeg(s.azimuth), se = sinDeg(s.elevation), ce = cosDeg(s.elevation);
    const openvdb::Vec3d d(sa * ce, -ca * ce, se); // towards the camera
    cam.forward = -d;
    cam.right = openvdb::Vec3d(ca, sa, 0.0);
    cam.up = cam.right.cross(cam.forward);
    cam.up.normalize();
    // Re-orthogonalise right against forward (exact up to rounding already).
    cam.right = cam.forward.cross(cam.up);
    cam.right.normalize();

    // Corners relative to the centre, in the camera frame.
    const double fill = 1.0 - s.margin;
    double maxX = 0, maxY = 0, radius = 0;
    std::vector<openvdb::Vec3d> rel;
    for (int c = 0; c < 8; ++c) {
        const openvdb::Vec3d p((c & 1) ? box.max()[0] : box.min()[0], (c & 2) ? box.max()[1] : box.min()[1],
                               (c & 4) ? box.max()[2] : box.min()[2]);
        const openvdb::Vec3d r = p - cam.target;
        rel.push_back(r);
        maxX = std::max(maxX, std::abs(r.dot(cam.right)));
        maxY = std::max(maxY, std::abs(r.dot(cam.up)));
        radius = std::max(radius, r.length());
    }
    radius = std::max(radius, 1e-12);
    const double aspect = double(s.width) / double(s.height);

    if (s.orthographic) {
        double h = s.orthoHeight ? *s.orthoHeight : std::max(2.0 * maxY, 2.0 * maxX / aspect) / fill;
        if (!(h > 0.0)) h = 2.0 * radius;
        cam.orthoHeight = h;
        cam.orthoWidth = h * aspect;
        cam.distance = s.distance ? *s.distance : 2.0 * radius;
    } else if (s.distance) {
        cam.distance = *s.distance;
    } else {
        const double ty = std::tan(radians(s.fovY) * 0.5) * fill;
        const double tx = ty * aspect;
        double dist = 0.0;
        for (const auto& r : rel) {
            const double depth = r.dot(d); // towards the camera
            dist = std::max(dist, depth + std::abs(r.dot(cam.right)) / tx);
            dist = std::max(dist, depth + std::abs(r.dot(cam.up)) / ty);
        }
        cam.distance = std::max(dist, 1e-9);
    }
    cam.position = cam.target + d * cam.distance;
    return cam;
}

std::pair<Camera, Camera> stereoPair(const Camera& centre, double eyeSeparation)
{
    if (!(eyeSeparation > 0.0 && std::isfinite(eyeSeparation)))
        throw InputError("eye separation " + num(eyeSeparation) + " is out of range; expected world units > 0");
    const double half = std::atan(0.5 * eyeSeparation / centre.distance);
    auto orbit = [&](double angle) {
        // Rotate position and frame about the axis `up` through the target (Rodrigues).
        const openvdb::Vec3d k = centre.up;
        auto rot = [&](const openvdb::Vec3d& v) {
            return v * std::cos(angle) + k.cross(v) * std::sin(angle) + k * (k.dot(v)) * (1.0 - std::cos(angle));
        };
        Camera c = centre;
        c.position = centre.target + rot(centre.position - centre.target);
        c.forward = rot(centre.forward);
        c.right = rot(centre.right);
        c.up = centre.up;
        return c;
    };
    // A rotation by +angle about `up` moves the camera towards +right (up × d = right): that is
    // the right eye.
    Camera right = orbit(half), left = orbit(-half);
    left.azimuth = right.azimuth = centre.azimuth;
    return {left, right};
}

// ---- images ---------------------------------------------------------------------------------

StereoMode stereoFromString(const std::string& s) { return valueOf<StereoMode>(kStereoNames, s, "stereo mode"); }

const char* toString(StereoMode m) { return nameOf<StereoMode>(kStereoNames, m); }

Image sideBySide(const Image& l, const Image& r)
{
    if (l.width != r.width || l.height != r.height) throw Error("stereo eyes differ in size");
    Image out(l.width * 2, l.height);
    for (int y = 0; y < l.height; ++y) {
        std::copy_n(l.pixel(0, y), 4 * l.width, out.pixel(0, y));
        std::copy_n(r.pixel(0, y), 4 * r.width, out.pixel(l.width, y));
    }
    return out;
}

Image anaglyph(const Image& l, const Image& r)
{
    if (l.width != r.width || l.height != r.height) throw Error("stereo eyes differ in size");
    Image out(l.width, l.height);
    for (std::size_t i = 0; i < out.rgba.size(); i += 4) {
        out.rgba[i + 0] = l.rgba[i + 0];
        out.rgba[i + 1] = r.rgba[i + 1];
        out.rgba[i + 2] = r.rgba[i + 2];
        out.rgba[i + 3] = std::max(l.rgba[i + 3], r.rgba[i + 3]);
    }
    return out;
}

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
        return InputError(what + " " + num(v) + " is out of range; expected " + expected);
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

    void renderTile(const Camera& cam, Image& img, int x0, int y0, int x1, int y1, RenderStats& st) const;
    void renderPixel(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st, const openvdb::Vec3d& light,
                     bool headlight) const;
    template<bool Lit, bool Halo, bool Colored>
    void march(const openvdb::math::Ray<double>& ray, float* px, RenderStats& st, const openvdb::Vec3d& light,
               bool headlight) const;
};

HaloRaycaster::HaloRaycaster(const RenderVolume& vol, const RenderSettings& settings, Progress& progress)
    : mImpl(std::make_unique<Impl>())
{
    settings.validate();
    Impl& m = *mImpl;
    m.settings = settings;
    if (!vol.density) throw InputError("no density grid to render");
    requireLinear(*vol.density);
    for (const openvdb::GridBase* g : std::initializer_list<const openvdb::GridBase*>{
             vol.halo.get(), vol.color.get(), vol.scalar.get(), vol.tangent.get(), vol.flow.get()})
        if (g) requireLinear(*g);
    if (settings.colormap && !vol.scalar)
        throw InputError("a colormap needs a `scalar` grid to colour by, and there is none");

    m.xform = vol.density->transform().copy();
    m.worldToIndex = m.xform->baseMap()->getAffineMap()->getMat4().inverse();
    const openvdb::Vec3d vs = m.xform->voxelSize();
    m.voxelLength = std::min({vs[0], vs[1], vs[2]});

    openvdb::CoordBBox active = vol.density->evalActiveVoxelBoundingBox();
    if (vol.halo && settings.halos) {
        // The halo's active box, in density index space.
        const openvdb::CoordBBox hb = vol.halo->evalActiveVoxelBoundingBox();
        if (!hb.empty()) {
            if (vol.halo->transform() == *m.xform) active.expand(hb);
            else {
                const openvdb::BBoxd w = vol.halo->transform().indexToWorld(hb);
                const openvdb::BBoxd i = m.xform->worldToIndex(w);
                active.expand(openvdb::CoordBBox(openvdb::Coord::floor(i.min()), openvdb::Coord::ceil(i.max())));
            }
        }
    }
    if (active.empty() || vol.density->activeVoxelCount() == 0)
        throw InputError("grid '" + vol.density->getName() + "' has no active voxels; nothing to render");
    {
        openvdb::BBoxd ib(active.min().asVec3d() - openvdb::Vec3d(0.5), active.max().asVec3d() + openvdb::Vec3d(0.5));
        m.worldBox = m.xform->indexToWorld(ib);
    }

    // Dense arrays over [min − 1, max + 2]: samples lie in [min − 1, max + 1] (where trilinear
    // support ends), and the +1 neighbour of the last one must exist.
    const openvdb::CoordBBox dbox(active.min() - openvdb::Coord(1), active.max() + openvdb::Coord(2));
    const openvdb::Coord dim = dbox.dim();
    const double count = double(dim[0]) * double(dim[1]) * double(dim[2]);
    if (count > double(std::numeric_limits<int>::max()))
        throw InputError("the active bounding box of '" + vol.density->getName() + "' (" + std::to_string(dim[0]) + "x" +
                         std::to_string(dim[1]) + "x" + std::to_string(dim[2]) +
                         " voxels) is too large for the reference raycaster (at most 2^31 voxels)");
    m.nx = dim[0];
    m.ny = dim[1];
    m.nz = dim[2];
    m.origin = dbox.min().asVec3d();
    m.extent = openvdb::Vec3d(dim[0] - 2, dim[1] - 2, dim[2] - 2);
    const std::size_t n = std::size_t(count);

    {
        const ThreadLimit threadLimit(settings.threads);
        int stages = 1 + (vol.halo && settings.halos) + (vol.color || settings.colormap) + (vol.tangent || vol.flow);
        progress.begin("load", std::uint64_t(stages));
        m.density.assign(n, 0.0f);
        fillDense(*vol.density, *m.xform, dbox, m.density.data());
        if (m.settings.densityScale == 0.0 && vol.halo) {
            m.settings.densityScale = kAutoLineScale; // a line bake: each line nearly opaque
        } else if (m.settings.densityScale == 0.0) {
            // Auto: the mean windowed density over the box times the mean box depth (voxels)
            // gives the optical depth of an average ray; scale it to kAutoDepth. Summed per
            // z slice, then slices in order: the same value for any thread count.
            std::vector<double> slice(std::size_t(m.nz), 0.0);
            const double lo = settings.densityLow, inv = 1.0 / (settings.densityHigh - settings.densityLow);
            const std::size_t per = std::size_t(m.nx) * std::size_t(m.ny);
            tbb::parallel_for(tbb::blocked_range<int>(0, m.nz), [&](const tbb::blocked_range<int>& r) {
                for (int k = r.begin(); k != r.end(); ++k) {
                    double acc = 0.0;
                    for (std::size_t i = std::size_t(k) * per, e = i + per; i < e; ++i)
                        acc += std::clamp((double(m.density[i]) - lo) * inv, 0.0, 1.0);
                    slice[std::size_t(k)] = acc;
                }
            });
            double sum = 0.0;
            for (double v : slice) sum += v;
            const double mean = sum / double(n);
            const double depth = (active.dim()[0] + active.dim()[1] + active.dim()[2]) / 3.0;
            const double k = mean > 0.0 ? kAutoDepth / (mean * depth) : 1.0;
            m.settings.densityScale = std::clamp(k, 1e-3, 8.0);
        }
        progress.advance(1);
        detail::checkCancel(progress);
        if (vol.halo && settings.halos) {
            m.halo.assign(n, 0.0f);
            fillDense(*vol.halo, *m.xform, dbox, m.halo.data());
            m.useHalo = true;
            progress.advance(1);
        }
        detail::checkCancel(progress);
        if (settings.colormap) {
            std::vector<float> s(n, 0.0f);
            fillDense(*vol.scalar, *m.xform, dbox, s.data());
            // A 1024-entry table of the map, scene-linear.
            std::vector<openvdb::Vec3s> lut(1024);
            for (int i = 0; i < 1024; ++i) {
                const openvdb::Vec3d c = settings.colormap->linear(double(i) / 1023.0);
                lut[std::size_t(i)] = openvdb::Vec3s(float(c[0]), float(c[1]), float(c[2]));
            }
            m.color.resize(n);
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 16), [&](const auto& r) {
                for (std::size_t i = r.begin(); i != r.end(); ++i) {
                    const float v = std::clamp(s[i], 0.0f, 1.0f);
                    m.color[i] = lut[std::size_t(std::lround(v * 1023.0f))];
                }
            });
            progress.advance(1);
        } else if (vol.color) {
            m.color.assign(n, openvdb::Vec3s(0.0f));
            fillDense(*vol.color, *m.xform, dbox, m.color.data());
            progress.advance(1);
        }
        detail::checkCancel(progress);
        if (vol.tangent || vol.flow) {
            m.tangent.assign(n, openvdb::Vec3s(0.0f));
            fillDense(vol.tangent ? *vol.tangent : *vol.flow, *m.xform, dbox, m.tangent.data());
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 16), [&](const auto& r) {
                for (std::size_t i = r.begin(); i != r.end(); ++i) {
                    const float len = m.tangent[i].length();
                    m.tangent[i] = len > 1e-20f ? m.tangent[i] / len : openvdb::Vec3s(0.0f);
                }
            });
            progress.advance(1);
        }
        progress.end();

        // Brick occupancy: brick b covers local samples [8b, 8b + 8) and reads voxels
        // [8b, 8b + 8]. It can contribute if some voxel there is above the density window or,
        // with halos, above the halo threshold (a halo exit must still be seen).
        m.bx = int(std::floor(m.extent[0] / kBrick)) + 1;
        m.by = int(std::floor(m.extent[1] / kBrick)) + 1;
        m.bz = int(std::floor(m.extent[2] / kBrick)) + 1;
        m.brickActive.assign(std::size_t(m.bx) * std::size_t(m.by) * std::size_t(m.bz), 0);
        const float lo = float(settings.densityLow), thr = float(settings.haloThreshold);
        tbb::parallel_for(tbb::blocked_range<int>(0, m.bz), [&](const tbb::blocked_range<int>& r) {
            for (int c = r.begin(); c != r.end(); ++c)
                for (int b = 0; b < m.by; ++b)
                    for (int a = 0; a < m.bx; ++a) {
                        bool on = false;
                        for (int k = c * kBrick; k <= std::min(c * kBrick + kBrick, m.nz - 1) && !on; ++k)
                            for (int j = b * kBrick; j <= std::min(b * kBrick + kBrick, m.ny - 1) && !on; ++j) {
                                const std::size_t row = std::size_t(m.nx) * (std::size_t(j) + std::size_t(m.ny) * std::size_t(k));
                                for (int i = a * kBrick; i <= std::min(a * kBrick + kBrick, m.nx - 1); ++i) {
                                    if (m.density[row + std::size_t(i)] > lo ||
                                        (m.useHalo && m.halo[row + std::size_t(i)] > thr)) {
                                        on = true;
                                        break;
                                    }
                                }
                            }
                        m.brickActive[std::size_t(a) + std::size_t(m.bx) * (std::size_t(b) + std::size_t(m.by) * std::size_t(c))] = on;
                    }
        });
        m.haveTangent = !m.tangent.empty();
        if (!m.settings.lighting.enabled) std::vector<openvdb::Vec3s>().swap(m.tangent); // unlit: not needed
        if (!m.tangent.empty()) {
            m.packed.resize(n);
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1 << 16), [&](const auto& r) {
                for (std::size_t i = r.begin(); i != r.end(); ++i)
                    m.packed[i] = openvdb::Vec4f(m.density[i], m.tangent[i][0], m.tangent[i][1], m.tangent[i][2]);
            });
            std::vector<float>().swap(m.density);
            std::vector<openvdb::Vec3s>().swap(m.tangent);
        }
    }
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

} // namespace

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
    for (int a = 0; a < 3; ++a) {
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

    const RenderSettings& s = settings;
    const double dt = s.step * voxelLength; // world units per step
    const double tau = s.densityScale * s.step;  // optical depth per step at ρ' = 1
    const float lo = float(s.densityLow);
    const float invWindow = float(1.0 / (s.densityHigh - s.densityLow));
    const float thr = float(s.haloThreshold);
    const openvdb::Vec3f v(-ray.dir());
    const openvdb::Vec3f l = headlight ? v : openvdb::Vec3f(lightDir);
    const float ka = float(s.lighting.ambient), kd = float(s.lighting.diffuse), ks = float(s.lighting.specular);
    const float shin = float(s.lighting.shininess);
    const int shinInt = (shin == std::floor(shin) && shin <= 256.0f) ? int(shin) : -1;
    const float* dens = Lit ? nullptr : density.data();
    const openvdb::Vec4f* pk = Lit ? packed.data() : nullptr;
    const std::size_t sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);

    double T = 1.0, R = 0.0, G = 0.0, B = 0.0;
    bool inHalo = false;
    float haloMax = 0.0f;
    auto haloExit = [&] {
        inHalo = false;
        const double A = std::min(1.0, (1.0 - T) + s.haloStrength * double(haloMax));
        T = 1.0 - A;
    };

    // One sample at parameter t. Returns false when the ray is finished (opaque).
    auto sample = [&](double t) __attribute__((always_inline)) -> bool {
        ++st.samples;
        const openvdb::Vec3d q = q0 + qd * t;
        const double fx0 = std::floor(q[0]), fy0 = std::floor(q[1]), fz0 = std::floor(q[2]);
        int ix = int(fx0), iy = int(fy0), iz = int(fz0);
        ix = std::clamp(ix, 0, nx - 2);
        iy = std::clamp(iy, 0, ny - 2);
        iz = std::clamp(iz, 0, nz - 2);
        const float fx = float(std::clamp(q[0] - ix, 0.0, 1.0));
        const float fy = float(std::clamp(q[1] - iy, 0.0, 1.0));
        const float fz = float(std::clamp(q[2] - iz, 0.0, 1.0));
        const std::size_t i000 = std::size_t(ix) + sy * std::size_t(iy) + sz * std::size_t(iz);
        const float w[8] = {(1 - fx) * (1 - fy) * (1 - fz), fx * (1 - fy) * (1 - fz), (1 - fx) * fy * (1 - fz),
                            fx * fy * (1 - fz), (1 - fx) * (1 - fy) * fz, fx * (1 - fy) * fz,
                            (1 - fx) * fy * fz, fx * fy * fz};
        const std::size_t idx[8] = {i000, i000 + 1, i000 + sy, i000 + sy + 1,
                                    i000 + sz, i000 + sz + 1, i000 + sz + sy, i000 + sz + sy + 1};
        if constexpr (Halo) {
            float h = 0.0f;
            for (int c = 0; c < 8; ++c) h += w[c] * halo[idx[c]];
            if (h > thr) {
                if (!inHalo) {
                    inHalo = true;
                    haloMax = h;
                } else {
                    haloMax = std::max(haloMax, h);
                }
            } else if (inHalo) {
                haloExit();
            }
        }
        float rho = 0.0f;
        openvdb::Vec4f dtan(0.0f);
        if constexpr (Lit) {
            for (int c = 0; c < 8; ++c) dtan += pk[idx[c]] * w[c];
            rho = dtan[0];
        } else {
            for (int c = 0; c < 8; ++c) rho += w[c] * dens[idx[c]];
        }
        if (rho > lo) {
            const float rw = std::min(1.0f, (rho - lo) * invWindow);
            const double alpha = 1.0 - double(std::exp(-float(tau) * rw));
            const double weight = T * alpha * s.brightness;
            if (weight > 1e-9) {
                openvdb::Vec3f c(1.0f);
                if constexpr (Colored) {
                    // Density-weighted: colour belongs to the lines, so voxels without density
                    // (outside the colour grid's active region: black) do not darken line edges.
                    openvdb::Vec3f cs(0.0f);
                    for (int k = 0; k < 8; ++k) {
                        const float dk = Lit ? pk[idx[k]][0] : dens[idx[k]];
                        cs += color[idx[k]] * (w[k] * dk);
                    }
                    c = cs / rho;
                }
                float spec = 0.0f;
                if constexpr (Lit) {
                    // Zöckler et al.: diffuse √(1−(L·T)²), V·R = √(1−(L·T)²)·√(1−(V·T)²) − (L·T)(V·T).
                    const openvdb::Vec3f ts(dtan[1], dtan[2], dtan[3]);
                    const float len2 = ts.lengthSqr();
                    float diff = ka + kd;
                    if (len2 > 1e-12f) {
                        const float inv = 1.0f / std::sqrt(len2);
                        const float lt = l.dot(ts) * inv, vt = v.dot(ts) * inv;
                        // √(1 − (L·T)²) = |L × T| for unit vectors, accurate near parallel.
                        const float sl = l.cross(ts).length() * inv;
                        const float sv = v.cross(ts).length() * inv;
                        const float vr = sl * sv - lt * vt;
                        diff = ka + kd * sl;
                        spec = vr > 0.0f ? ks * specPow(vr, shin, shinInt) : 0.0f;
                    }
                    c *= diff;
                }
                R += weight * (c[0] + spec);
                G += weight * (c[1] + spec);
                B += weight * (c[2] + spec);
            }
            T *= 1.0 - alpha;
            if (T < s.minTransmittance) return false;
        }
        return true;
    };

    const double span = t1 - t0;
    const std::int64_t kEnd = std::int64_t(std::ceil(span / dt - 0.5)); // samples k with t0 + (k+½)dt < t1
    auto tk = [&](std::int64_t k) { return t0 + (double(k) + 0.5) * dt; };

    if (!s.emptySpaceSkipping) {
        for (std::int64_t k = 0; k < kEnd; ++k)
            if (tk(k) < t1 && !sample(tk(k))) break;
    } else {
        // 3D DDA over 8³ bricks (Amanatides & Woo).
        const openvdb::Vec3d qs = q0 + qd * t0;
        int cell[3], stepc[3], nb[3] = {bx, by, bz};
        double tNext[3], tDelta[3];
        for (int a = 0; a < 3; ++a) {
            cell[a] = std::clamp(int(std::floor(qs[a] / kBrick)), 0, nb[a] - 1);
            if (qd[a] > 1e-15) {
                stepc[a] = 1;
                tNext[a] = ((cell[a] + 1) * double(kBrick) - q0[a]) / qd[a];
                tDelta[a] = kBrick / qd[a];
            } else if (qd[a] < -1e-15) {
                stepc[a] = -1;
                tNext[a] = (cell[a] * double(kBrick) - q0[a]) / qd[a];
                tDelta[a] = -kBrick / qd[a];
            } else {
                stepc[a] = 0;
                tNext[a] = tDelta[a] = std::numeric_limits<double>::infinity();
            }
        }
        std::int64_t k = 0;
        double tc = t0;
        bool prevActive = true;
        while (true) {
            const double tExit = std::min({tNext[0], tNext[1], tNext[2], t1});
            const bool on = brickActive[std::size_t(cell[0]) +
                                        std::size_t(bx) * (std::size_t(cell[1]) + std::size_t(by) * std::size_t(cell[2]))];
            if (on) {
                if (!prevActive) k = std::max(k, std::int64_t(std::ceil((tc - t0) / dt - 0.5)));
                bool alive = true;
                for (; k < kEnd && tk(k) < tExit; ++k)
                    if (!sample(tk(k))) {
                        alive = false;
                        break;
                    }
                if (!alive) break;
            } else {
                ++st.skippedBricks;
                if (inHalo) haloExit();
            }
            prevActive = on;
            if (tExit >= t1 || k >= kEnd) break;
            int a = 0;
            if (tNext[1] < tNext[a]) a = 1;
            if (tNext[2] < tNext[a]) a = 2;
            cell[a] += stepc[a];
            if (cell[a] < 0 || cell[a] >= nb[a]) break;
            tc = tNext[a];
            tNext[a] += tDelta[a];
        }
    }
    px[0] = float(R);
    px[1] = float(G);
    px[2] = float(B);
    px[3] = float(1.0 - T);
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

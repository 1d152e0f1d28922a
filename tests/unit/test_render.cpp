// Tests of the reference halo raycaster (lic/render/Raycaster.h) and image output (vdbexport/io/ImageIO.h):
// closed forms (slab transmittance, line lighting), the halo effect on two crossing lines,
// camera conventions, determinism, stereo, and EXR/PNG/GIF through OIIO and OCIO.
#include "lic/util/Error.h"
#include "lic/render/Raycaster.h"
#include "render/LeafTable.h" // internal: where samples read the grids

#include "TempDirSuite.h"

#include "vdbexport/io/ImageIO.h"
#include "vdbexport/render/Render.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>

#include <unistd.h>

using namespace lic;
using openvdb::Vec3d;
namespace fs = std::filesystem;

namespace {

/// A float grid with voxel size h, voxel (0,0,0) at the world origin, filled with f(world) over
/// the index box [lo, hi] (values ≤ 0 left inactive).
openvdb::FloatGrid::Ptr makeScalar(const std::string& name, double h, const openvdb::Coord& lo, const openvdb::Coord& hi,
                                   const std::function<double(const Vec3d&)>& f)
{
    openvdb::initialize();
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(h));
    g->setName(name);
    auto acc = g->getAccessor();
    for (int i = lo[0]; i <= hi[0]; ++i)
        for (int j = lo[1]; j <= hi[1]; ++j)
            for (int k = lo[2]; k <= hi[2]; ++k) {
                const openvdb::Coord c(i, j, k);
                const double v = f(g->transform().indexToWorld(c));
                if (v > 0.0) acc.setValueOn(c, float(v));
            }
    return g;
}

openvdb::Vec3SGrid::Ptr makeConstVec(const std::string& name, const openvdb::FloatGrid& like, const Vec3d& v)
{
    auto g = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    g->setTransform(like.transform().copy());
    g->setName(name);
    g->tree().topologyUnion(like.tree());
    for (auto it = g->beginValueOn(); it; ++it) it.setValue(openvdb::Vec3s(float(v[0]), float(v[1]), float(v[2])));
    return g;
}

/// Distance from p to the line through a with unit direction d.
double lineDistance(const Vec3d& p, const Vec3d& a, const Vec3d& d)
{
    const Vec3d r = p - a;
    return (r - d * r.dot(d)).length();
}

/// A camera looking straight at the origin from `view`, orthographic, `height` world units tall.
Camera orthoCamera(View view, double height, int w, int h, const openvdb::BBoxd& box)
{
    CameraSettings cs;
    std::tie(cs.azimuth, cs.elevation) = viewAngles(view);
    cs.orthographic = true;
    cs.orthoHeight = height;
    cs.width = w;
    cs.height = h;
    return makeCamera(cs, box);
}

RenderSettings exact()
{
    RenderSettings s;
    s.densityScale = 1.0;     // not auto
    s.minTransmittance = 0.0; // no early termination: exact sums
    return s;
}

/// Both raycasters' images through the camera `cs` frames on `a`'s box: not empty (the sum of
/// the RGBA values above `minSum`) and the same bits.
void expectSameImage(const HaloRaycaster& a, const HaloRaycaster& b, const CameraSettings& cs, double minSum)
{
    const Camera cam = makeCamera(cs, a.worldBBox());
    const Image ia = a.render(cam), ib = b.render(cam);
    double sum = 0;
    for (float v : ia.rgba) sum += v;
    ASSERT_GT(sum, minSum) << "the test image must not be empty";
    ASSERT_EQ(ia.rgba.size(), ib.rgba.size());
    EXPECT_EQ(0, std::memcmp(ia.rgba.data(), ib.rgba.data(), ia.rgba.size() * sizeof(float)));
}

} // namespace

// ---- closed forms ---------------------------------------------------------------------------

// A slab of uniform density ρ, N voxels thick: the trilinear reconstruction integrates to ρ·N
// voxel lengths along any ray through both faces, so a perpendicular ray transmits exp(−K ρ N)
// exactly (midpoint steps of half a voxel starting on a voxel centre integrate the piecewise
// linear profile exactly), and an oblique one at angle θ transmits exp(−K ρ N / cos θ).
TEST(Render, UniformSlabTransmittanceIsExponential)
{
    for (const double h : {1.0, 0.25}) {
        for (const bool skipping : {true, false}) {
            const int N = 6;
            const double rho = 0.7, K = 0.45;
            auto d = makeScalar("density", h, {0, -12, -12}, {N - 1, 12, 12}, [&](const Vec3d&) { return rho; });
            RenderSettings s = exact();
            s.densityScale = K;
            s.emptySpaceSkipping = skipping;
            RenderVolume vol;
            vol.density = d;
            HaloRaycaster rc(vol, s);
            // Left view: camera on −X looking along +X, through the slab's two faces.
            const Camera cam = orthoCamera(View::Left, 4.0 * h, 8, 8, rc.worldBBox());
            const Image img = rc.render(cam);
            const double expected = 1.0 - std::exp(-K * rho * N);
            for (int y = 0; y < 8; ++y)
                for (int x = 0; x < 8; ++x) {
                    const float* p = img.pixel(x, y);
                    EXPECT_NEAR(p[3], expected, 2e-6) << "h " << h << " pixel " << x << "," << y;
                    // White emission proportional to absorption sums to the opacity.
                    EXPECT_NEAR(p[0], expected, 2e-6);
                    EXPECT_NEAR(p[1], p[0], 1e-7);
                }

            // Oblique: azimuth −60° looks along (cos 30°, sin 30°, 0), 30° off the slab normal.
            // Steps no longer start on voxel centres, so the midpoint rule errs at the two kinks
            // of the profile (O(step²)): use ⅛-voxel steps and a 2·10⁻⁴ relative tolerance.
            s.step = 0.125;
            HaloRaycaster fine(vol, s);
            CameraSettings cs;
            cs.azimuth = -60.0;
            cs.orthographic = true;
            cs.orthoHeight = 2.0 * h;
            cs.width = cs.height = 4;
            const Image obl = fine.render(makeCamera(cs, rc.worldBBox()));
            const double tau = K * rho * N / std::cos(30.0 * 3.14159265358979323846 / 180.0);
            for (int y = 0; y < 4; ++y)
                for (int x = 0; x < 4; ++x)
                    EXPECT_NEAR(-std::log(1.0 - obl.pixel(x, y)[3]), tau, 2e-4 * tau) << "oblique pixel " << x << "," << y;
        }
    }
}

TEST(Render, DensityRangeWindowsTheTransfer)
{
    // ρ = 0.6 through the window [0.2, 1.0] acts as ρ' = 0.5. The slab ends (where the trilinear
    // ramp crosses the window edge) are the same for slabs of 4 and 8 voxels, so the optical
    // depths differ by exactly K·ρ'·4 = 2.
    auto tauOf = [](int n, double lo) {
        auto d = makeScalar("density", 1.0, {0, -8, -8}, {n - 1, 8, 8}, [](const Vec3d&) { return 0.6; });
        RenderVolume vol;
        vol.density = d;
        RenderSettings s = exact();
        s.densityLow = lo;
        s.densityHigh = 1.0;
        HaloRaycaster rc(vol, s);
        return -std::log(1.0 - double(rc.render(orthoCamera(View::Left, 2.0, 2, 2, rc.worldBBox())).pixel(0, 0)[3]));
    };
    EXPECT_NEAR(tauOf(8, 0.2) - tauOf(4, 0.2), 2.0, 1e-4);
    EXPECT_NEAR(tauOf(8, 0.0) - tauOf(4, 0.0), 0.6 * 4, 1e-4);
    EXPECT_EQ(tauOf(4, 0.6), 0.0) << "density at or below the window is transparent";
}

// Illuminated lines (Zöckler et al.): for a line of tangent T, light L and eye V,
// shade = ambient + diffuse·√(1−(L·T)²) + specular·max(V·R, 0)^n,
// V·R = √(1−(L·T)²)·√(1−(V·T)²) − (L·T)(V·T). With a constant tangent the shade is constant along
// the ray, so pixel colour / pixel alpha must equal it exactly.
TEST(Render, IlluminationFollowsTheLineLightingFormula)
{
    auto d = makeScalar("density", 1.0, {-10, -3, -3}, {10, 3, 3},
                        [](const Vec3d& p) { return std::max(0.0, 1.0 - lineDistance(p, Vec3d(0), Vec3d(1, 0, 0)) / 2.5); });
    const Vec3d V(0, -1, 0); // towards the eye of the front view
    for (const bool headlight : {false, true}) {
        Lighting lt;
        lt.headlight = headlight;
        lt.direction = Vec3d(1, -1, 1);
        lt.ambient = 0.2;
        lt.diffuse = 0.8;
        lt.specular = 0.35;
        lt.shininess = 16;
        const Vec3d L = headlight ? V : lt.direction.unit();
        std::vector<double> shades;
        for (const Vec3d& T0 : {Vec3d(1, 0, 0), Vec3d(0, 0, 1), Vec3d(0, 1, 0), Vec3d(1, -1, 1), Vec3d(1, 1, 0),
                                Vec3d(0.3, -0.2, 0.9), Vec3d(-1, 1, -1)}) {
            const Vec3d T = T0.unit();
            RenderVolume vol;
            vol.density = d;
            vol.tangent = makeConstVec("tangent", *d, T);
            RenderSettings s = exact();
            s.lighting = lt;
            HaloRaycaster rc(vol, s);
            const Image img = rc.render(orthoCamera(View::Front, 2.0, 3, 3, rc.worldBBox()));
            const float* p = img.pixel(1, 1);
            ASSERT_GT(p[3], 0.5f);
            const double lt1 = L.dot(T), vt = V.dot(T);
            const double diff = std::sqrt(std::max(0.0, 1.0 - lt1 * lt1));
            const double vr = diff * std::sqrt(std::max(0.0, 1.0 - vt * vt)) - lt1 * vt;
            const double expected = 0.2 + 0.8 * diff + 0.35 * std::pow(std::max(vr, 0.0), 16.0);
            EXPECT_NEAR(p[0] / p[3], expected, 1e-5) << "T " << T << " headlight " << headlight;
            EXPECT_NEAR(p[2] / p[3], expected, 1e-5);
            shades.push_back(p[0] / p[3]);
        }
        if (!headlight) {
            // T ∥ L (the 4th direction) is the darkest: ambient only, no specular.
            EXPECT_NEAR(shades[3], 0.2, 1e-5);
            for (std::size_t i = 0; i < shades.size(); ++i) EXPECT_GE(shades[i], shades[3] - 1e-9);
        } else {
            // Headlight: a line seen end-on (T = V) is ambient only; lines across the view are
            // fully lit with the specular peak (V·R = 1).
            EXPECT_NEAR(shades[2], 0.2, 1e-5);
            EXPECT_NEAR(shades[0], 0.2 + 0.8 + 0.35, 1e-5);
            EXPECT_NEAR(shades[1], 0.2 + 0.8 + 0.35, 1e-5);
        }
    }
    // The public helper agrees with the formula too.
    Lighting lt;
    const auto [a, sp] = lineShade(lt, Vec3d(1, 0, 0), Vec3d(0, 0, 1), Vec3d(0, -1, 0));
    EXPECT_NEAR(a, lt.ambient + lt.diffuse, 1e-12);
    EXPECT_NEAR(sp, lt.specular, 1e-12);
}

TEST(Render, ColourComesFromTheColorGridOrTheColormap)
{
    auto d = makeScalar("density", 1.0, {-3, -3, -3}, {3, 3, 3}, [](const Vec3d&) { return 1.0; });
    RenderVolume vol;
    vol.density = d;
    vol.color = makeConstVec("color", *d, Vec3d(0.5, 0.2, 0.1));
    RenderSettings s = exact();
    const float* p = nullptr;
    HaloRaycaster rc(vol, s);
    Image img = rc.render(orthoCamera(View::Front, 2.0, 3, 3, rc.worldBBox()));
    p = img.pixel(1, 1);
    EXPECT_NEAR(p[0] / p[3], 0.5, 1e-5);
    EXPECT_NEAR(p[1] / p[3], 0.2, 1e-5);
    EXPECT_NEAR(p[2] / p[3], 0.1, 1e-5);

    // A colormap over `scalar` (here 1 everywhere) wins over `color`.
    vol.scalar = makeScalar("scalar", 1.0, {-3, -3, -3}, {3, 3, 3}, [](const Vec3d&) { return 1.0; });
    s.colormap = Colormap::named("magma");
    HaloRaycaster rc2(vol, s);
    img = rc2.render(orthoCamera(View::Front, 2.0, 3, 3, rc2.worldBBox()));
    p = img.pixel(1, 1);
    const Vec3d top = Colormap::named("magma").linear(1.0);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(p[c] / p[3], top[c], 1e-4);

    vol.scalar.reset();
    EXPECT_THROW(HaloRaycaster(vol, s), InputError);
}

// ---- the halo effect ------------------------------------------------------------------------

// Two lines crossing at different depths, seen from the front (along +Y): the front line F runs
// along X at y = −10, the back line B along Z at y = +10. Both have halos (radius 8 voxels) around
// lines of radius 2.5. With halos on, B right beside F (inside F's halo, outside its line) must
// lose at least half its brightness; F itself must not be dimmed (first-halo rule).
TEST(Render, HalosCutTheBackLineBesideTheFrontLine)
{
    const Vec3d aF(0, -10, 0), dF(1, 0, 0), aB(0, 10, 0), dB(0, 0, 1);
    const double rLine = 2.5, rHalo = 8.0;
    auto lineF = [&](const Vec3d& p) { return std::max(0.0, 1.0 - lineDistance(p, aF, dF) / rLine); };
    auto lineB = [&](const Vec3d& p) { return std::max(0.0, 1.0 - lineDistance(p, aB, dB) / rLine); };
    auto haloF = [&](const Vec3d& p) { return std::max(0.0, 1.0 - lineDistance(p, aF, dF) / rHalo); };
    auto haloB = [&](const Vec3d& p) { return std::max(0.0, 1.0 - lineDistance(p, aB, dB) / rHalo); };
    const openvdb::Coord lo(-24, -20, -24), hi(24, 20, 24);
    RenderVolume both, frontOnly;
    both.density = makeScalar("density", 1.0, lo, hi, [&](const Vec3d& p) { return std::max(lineF(p), lineB(p)); });
    both.halo = makeScalar("halo", 1.0, lo, hi, [&](const Vec3d& p) { return std::max(haloF(p), haloB(p)); });
    frontOnly.density = makeScalar("density", 1.0, lo, hi, lineF);
    frontOnly.halo = makeScalar("halo", 1.0, lo, hi, haloF);

    RenderSettings on = exact(), off = exact();
    off.halos = false;
    HaloRaycaster rOn(both, on), rOff(both, off), rFront(frontOnly, on);
    ASSERT_TRUE(rOn.hasHalo());
    ASSERT_FALSE(rOff.hasHalo());
    // 96 × 96 pixels over 48 × 48 world units centred on the origin: pixel size ½.
    const Camera cam = orthoCamera(View::Front, 48.0, 96, 96, rOn.worldBBox());
    ASSERT_NEAR(cam.target[0], 0.0, 1e-9);
    ASSERT_NEAR(cam.target[2], 0.0, 1e-9);
    const Image imOn = rOn.render(cam), imOff = rOff.render(cam), imFront = rFront.render(cam);
    // Pixel of world (x, z) on the image plane: column (x + 24)·2, row (24 − z)·2.
    auto at = [](const Image& im, double x, double z) { return im.pixel(int((x + 24) * 2), int((24 - z) * 2)); };

    // B beside F: x = 0.25 (on B's axis), z = ±2.75, ±3.25 (just outside F's line, radius 2.5,
    // inside its halo).
    for (const double z : {2.75, -2.75, 3.25, -3.25}) {
        const float bOff = at(imOff, 0.25, z)[0], bOn = at(imOn, 0.25, z)[0];
        ASSERT_GT(bOff, 0.5f) << "the back line must be visible with halos off at z " << z;
        EXPECT_LE(bOn, 0.5f * bOff) << "z " << z << ": halos on " << bOn << ", off " << bOff;
    }
    // Far from F (outside its halo) B is untouched: its own halo is the first one on the ray.
    for (const double z : {12.25, -15.25}) EXPECT_FLOAT_EQ(at(imOn, 0.25, z)[0], at(imOff, 0.25, z)[0]) << z;
    // F away from B: identical with halos on and off.
    for (const double x : {-15.25, 14.75, 20.25}) {
        EXPECT_GT(at(imOn, x, 0.25)[0], 0.5f);
        EXPECT_FLOAT_EQ(at(imOn, x, 0.25)[0], at(imOff, x, 0.25)[0]) << x;
    }
    // F in front of B: not dimmed; B behind it is cut (on ≈ F alone ≤ off).
    for (const double z : {0.25, -0.25, 1.25}) {
        const float fOn = at(imOn, 0.25, z)[0], fAlone = at(imFront, 0.25, z)[0], fOff = at(imOff, 0.25, z)[0];
        EXPECT_GE(fOn, fAlone - 1e-6f) << z;
        EXPECT_LE(fOn, fOff + 1e-6f) << z;
    }
    // Halo strength 0 is the same as halos off.
    RenderSettings zero = exact();
    zero.haloStrength = 0.0;
    HaloRaycaster rZero(both, zero);
    const Image imZero = rZero.render(cam);
    for (std::size_t i = 0; i < imZero.rgba.size(); ++i) ASSERT_NEAR(imZero.rgba[i], imOff.rgba[i], 1e-6f);
}

TEST(Render, HaloTracksEntriesExitsAndMaximumAlongARay)
{
    // Along +X: a halo-only slab of 0.3 (voxels x = 2…5), one of 0.5 (x = 10…13), then a line slab
    // (density 1, halo 1, x = 20…23). Both exits before the line raise A: 0.3 + 0.5, so the line
    // arrives with transmittance 0.2 — exactly 0.2 × its brightness with halos off.
    auto d = makeScalar("density", 1.0, {20, -6, -6}, {23, 6, 6}, [](const Vec3d&) { return 1.0; });
    // The line's halo reaches past its density (x = 20…26), so its own exit comes after it.
    auto h = makeScalar("halo", 1.0, {0, -6, -6}, {26, 6, 6}, [](const Vec3d& p) {
        if (p[0] >= 2 && p[0] <= 5) return 0.3;
        if (p[0] >= 10 && p[0] <= 13) return 0.5;
        if (p[0] >= 20) return 1.0;
        return 0.0;
    });
    RenderVolume vol;
    vol.density = d;
    vol.halo = h;
    RenderSettings s = exact();
    HaloRaycaster rc(vol, s);
    RenderSettings off = s;
    off.halos = false;
    HaloRaycaster rcOff(vol, off);
    const Camera cam = orthoCamera(View::Left, 2.0, 2, 2, rc.worldBBox());
    const float on = rc.render(cam).pixel(0, 0)[0], offv = rcOff.render(cam).pixel(0, 0)[0];
    ASSERT_GT(offv, 0.9f);
    EXPECT_NEAR(on / offv, 0.2, 1e-5);
    // Strength 0.5 halves each raise: A = 0.15 + 0.25.
    s.haloStrength = 0.5;
    HaloRaycaster rcHalf(vol, s);
    EXPECT_NEAR(rcHalf.render(cam).pixel(0, 0)[0] / offv, 0.6, 1e-5);
    // Threshold 0.4: the first slab is not a halo any more; only the 0.5 exit counts.
    s.haloStrength = 1.0;
    s.haloThreshold = 0.4;
    HaloRaycaster rcThr(vol, s);
    EXPECT_NEAR(rcThr.render(cam).pixel(0, 0)[0] / offv, 0.5, 1e-5);
}

// ---- cameras --------------------------------------------------------------------------------

TEST(Render, NamedViewsFollowBlenderConventions)
{
    const openvdb::BBoxd box(Vec3d(-1, -2, -3), Vec3d(1, 2, 3));
    struct Case { View v; Vec3d fwd, right, up; };
    const Case cases[] = {
        {View::Front, {0, 1, 0}, {1, 0, 0}, {0, 0, 1}},   {View::Back, {0, -1, 0}, {-1, 0, 0}, {0, 0, 1}},
        {View::Right, {-1, 0, 0}, {0, 1, 0}, {0, 0, 1}},  {View::Left, {1, 0, 0}, {0, -1, 0}, {0, 0, 1}},
        {View::Top, {0, 0, -1}, {1, 0, 0}, {0, 1, 0}},    {View::Bottom, {0, 0, 1}, {1, 0, 0}, {0, -1, 0}},
    };
    for (const auto& c : cases) {
        for (const bool ortho : {false, true}) {
            CameraSettings cs;
            std::tie(cs.azimuth, cs.elevation) = viewAngles(c.v);
            cs.orthographic = ortho;
            cs.width = 200;
            cs.height = 100;
            const Camera cam = makeCamera(cs, box);
            EXPECT_LT((cam.forward - c.fwd).length(), 1e-9) << toString(c.v);
            EXPECT_LT((cam.right - c.right).length(), 1e-9) << toString(c.v);
            EXPECT_LT((cam.up - c.up).length(), 1e-9) << toString(c.v);
            EXPECT_LT((cam.right.cross(cam.up) + cam.forward).length(), 1e-9) << "right-handed";
            EXPECT_LT((cam.position + cam.forward * cam.distance - Vec3d(0)).length(), 1e-9);
            // Every corner of the box is in the frame, and the fit is tight (some corner is within
            // the margin of an edge).
            double maxU = 0;
            for (int k = 0; k < 8; ++k) {
                const Vec3d p((k & 1) ? 1 : -1, (k & 2) ? 2 : -2, (k & 4) ? 3 : -3);
                const Vec3d r = p - cam.position;
                double u, v;
                if (ortho) {
                    u = r.dot(cam.right) / (0.5 * cam.orthoWidth);
                    v = r.dot(cam.up) / (0.5 * cam.orthoHeight);
                } else {
                    const double z = r.dot(cam.forward);
                    ASSERT_GT(z, 0.0);
                    const double ty = std::tan(cam.fovY * 3.14159265358979323846 / 360.0);
                    u = r.dot(cam.right) / z / (ty * 2.0);
                    v = r.dot(cam.up) / z / ty;
                }
                EXPECT_LE(std::abs(u), 1.0 + 1e-9) << toString(c.v);
                EXPECT_LE(std::abs(v), 1.0 + 1e-9) << toString(c.v);
                maxU = std::max({maxU, std::abs(u), std::abs(v)});
            }
            EXPECT_NEAR(maxU, 1.0 - cs.margin, 1e-6) << toString(c.v) << (ortho ? " ortho" : " persp");
        }
    }
    EXPECT_THROW(viewFromString("side"), InputError);
}

TEST(Render, ImageOrientationMatchesTheView)
{
    // A blob at +X and one at +Z: in the front view the first is on the right, the second at the top.
    auto d = makeScalar("density", 1.0, {-12, -4, -12}, {12, 4, 12}, [](const Vec3d& p) {
        // A faint background keeps the whole box active, so the view is centred on the origin.
        return 0.001 + std::max(0.0, 1.0 - (p - Vec3d(8, 0, 0)).length() / 3.0) +
               std::max(0.0, 1.0 - (p - Vec3d(0, 0, 8)).length() / 3.0);
    });
    RenderVolume vol;
    vol.density = d;
    HaloRaycaster rc(vol, exact());
    const Image img = rc.render(orthoCamera(View::Front, 26.0, 26, 26, rc.worldBBox()));
    // Centre of mass of the bright pixels in each half.
    auto bright = [&](int x, int y) { return img.pixel(x, y)[3] > 0.3f; };
    EXPECT_TRUE(bright(21, 13)) << "+X blob on the right";
    EXPECT_FALSE(bright(4, 13)) << "nothing on the left";
    EXPECT_TRUE(bright(13, 4)) << "+Z blob at the top";
    EXPECT_FALSE(bright(13, 21)) << "nothing at the bottom";
    // Top view: +X right; with the +X blob at y = 0 it stays in the middle row.
    const Image top = rc.render(orthoCamera(View::Top, 26.0, 26, 26, rc.worldBBox()));
    EXPECT_GT(top.pixel(21, 13)[3], 0.3f);
}

TEST(Render, StereoPairOrbitsTheTarget)
{
    const openvdb::BBoxd box(Vec3d(-1), Vec3d(1));
    CameraSettings cs;
    cs.width = 40;
    cs.height = 30;
    const Camera c = makeCamera(cs, box);
    const auto [l, r] = stereoPair(c, 0.2);
    EXPECT_LT((l.position - c.position).dot(c.right), 0.0) << "left eye on the left";
    EXPECT_GT((r.position - c.position).dot(c.right), 0.0);
    EXPECT_NEAR((l.position - r.position).length(), 2 * c.distance * std::sin(std::atan(0.1 / c.distance)), 1e-9);
    EXPECT_NEAR((l.position - c.target).length(), c.distance, 1e-9);
    EXPECT_LT((l.position + l.forward * c.distance - c.target).length(), 1e-9) << "eyes converge on the target";
    Image a(40, 30), b(40, 30);
    a.pixel(3, 4)[0] = 1.0f;
    b.pixel(3, 4)[1] = 1.0f;
    const Image sbs = sideBySide(a, b);
    EXPECT_EQ(sbs.width, 80);
    EXPECT_EQ(sbs.height, 30);
    EXPECT_EQ(sbs.pixel(3, 4)[0], 1.0f);
    EXPECT_EQ(sbs.pixel(43, 4)[1], 1.0f);
    const Image ana = anaglyph(a, b);
    EXPECT_EQ(ana.width, 40);
    EXPECT_EQ(ana.pixel(3, 4)[0], 1.0f);
    EXPECT_EQ(ana.pixel(3, 4)[1], 1.0f);
    EXPECT_THROW(stereoPair(c, 0.0), InputError);
}

// ---- determinism ----------------------------------------------------------------------------

TEST(Render, BitIdenticalForAnyThreadCountAndWithOrWithoutSkipping)
{
    // A sparse, irregular volume with halos, colour and tangents.
    auto hash = [](const Vec3d& p) {
        const double s = std::sin(p[0] * 12.9898 + p[1] * 78.233 + p[2] * 37.719) * 43758.5453;
        return s - std::floor(s);
    };
    auto d = makeScalar("density", 0.5, {-20, -20, -20}, {20, 20, 20},
                        [&](const Vec3d& p) { return p.length() < 8 && hash(p) > 0.6 ? hash(p * 2.0) : 0.0; });
    auto h = makeScalar("halo", 0.5, {-20, -20, -20}, {20, 20, 20},
                        [&](const Vec3d& p) { return p.length() < 8.5 && hash(p) > 0.4 ? 0.5 : 0.0; });
    RenderVolume vol;
    vol.density = d;
    vol.halo = h;
    vol.tangent = makeConstVec("tangent", *d, Vec3d(0.6, 0.0, 0.8));
    vol.color = makeConstVec("color", *d, Vec3d(0.9, 0.5, 0.2));
    CameraSettings cs;
    cs.azimuth = 33;
    cs.elevation = 21;
    cs.width = 70;
    cs.height = 45;
    Image ref;
    for (const int threads : {1, 2, 3}) {
        RenderSettings s;
        s.threads = threads;
        HaloRaycaster rc(vol, s);
        const Image img = rc.render(makeCamera(cs, rc.worldBBox()));
        if (ref.rgba.empty()) {
            ref = img;
            double sum = 0;
            for (float v : ref.rgba) sum += v;
            ASSERT_GT(sum, 10.0) << "the test image must not be empty";
        } else {
            ASSERT_EQ(0, std::memcmp(img.rgba.data(), ref.rgba.data(), ref.rgba.size() * sizeof(float)))
                << threads << " threads";
        }
    }
    RenderSettings noSkip;
    noSkip.emptySpaceSkipping = false;
    HaloRaycaster rc(vol, noSkip);
    RenderStats st;
    const Image img = rc.render(makeCamera(cs, rc.worldBBox()), nullProgress(), &st);
    EXPECT_GT(st.samples, 0u);
    for (std::size_t i = 0; i < img.rgba.size(); ++i) ASSERT_NEAR(img.rgba[i], ref.rgba[i], 1e-6f) << i;
}

// The raycaster reads the trees where they are: a region held as tiles renders exactly as the
// same region held as voxels (the tile path of the cell reads and of the brick table).
TEST(Render, TilesRenderAsTheirVoxels)
{
    openvdb::initialize();
    auto tiles = openvdb::FloatGrid::create(0.0f);
    tiles->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    tiles->setName("density");
    // 16³ voxels of 0.3 as tiles of 8³ (leaf-aligned), plus a few single voxels beside them.
    tiles->tree().fill(openvdb::CoordBBox(openvdb::Coord(-8), openvdb::Coord(7)), 0.3f, true);
    tiles->tree().setValueOn(openvdb::Coord(9, 2, 3), 0.8f);
    tiles->tree().setValueOn(openvdb::Coord(-10, 0, 0), 0.6f);
    ASSERT_GT(tiles->tree().activeTileCount(), 0u);
    auto voxels = tiles->deepCopy();
    voxels->tree().voxelizeActiveTiles();
    ASSERT_EQ(voxels->tree().activeTileCount(), 0u);
    CameraSettings cs;
    cs.azimuth = 27;
    cs.elevation = 14;
    cs.width = 40;
    cs.height = 30;
    RenderVolume a, b;
    a.density = tiles;
    b.density = voxels;
    const HaloRaycaster ra(a, RenderSettings{}), rb(b, RenderSettings{});
    EXPECT_EQ(ra.settings().densityScale, rb.settings().densityScale); // auto: the same sum over the box
    expectSameImage(ra, rb, cs, 1.0);
}

// A grid with another transform is sampled trilinearly at the centres of the density grid's
// voxels: the image equals that of a grid resampled so by hand.
TEST(Render, GridsWithAnotherTransformAreResampledOntoTheDensityVoxels)
{
    auto d = makeScalar("density", 0.5, {-12, -12, -12}, {12, 12, 12},
                        [](const Vec3d& p) { return p.length() < 4.0 ? 0.7 : 0.0; });
    // Colour on a finer, shifted lattice.
    auto fine = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    auto xf = openvdb::math::Transform::createLinearTransform(0.3);
    xf->postTranslate(Vec3d(0.07, -0.11, 0.05));
    fine->setTransform(xf);
    fine->setName("color");
    {
        auto acc = fine->getAccessor();
        for (int i = -18; i <= 18; ++i)
            for (int j = -18; j <= 18; ++j)
                for (int k = -18; k <= 18; ++k) {
                    const Vec3d p = xf->indexToWorld(openvdb::Coord(i, j, k));
                    acc.setValueOn(openvdb::Coord(i, j, k),
                                   openvdb::Vec3s(float(0.5 + 0.1 * p[0]), float(0.5 + 0.1 * p[1]), float(0.5 - 0.1 * p[2])));
                }
    }
    // By hand: on density's voxels over its active box, padded by 2.
    auto hand = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    hand->setTransform(d->transform().copy());
    hand->setName("color");
    {
        openvdb::CoordBBox box = d->evalActiveVoxelBoundingBox();
        box.expand(2);
        auto src = fine->getConstAccessor();
        openvdb::tools::GridSampler<decltype(src), openvdb::tools::BoxSampler> sampler(src, fine->transform());
        auto acc = hand->getAccessor();
        for (auto ijk = box.begin(); ijk; ++ijk)
            acc.setValueOn(*ijk, sampler.wsSample(d->transform().indexToWorld(*ijk)));
    }
    RenderVolume a, b;
    a.density = b.density = d;
    a.color = fine;
    b.color = hand;
    CameraSettings cs;
    cs.azimuth = 40;
    cs.elevation = 25;
    cs.width = 36;
    cs.height = 36;
    const HaloRaycaster ra(a, exact()), rb(b, exact());
    expectSameImage(ra, rb, cs, 1.0);
}

// Where samples read the grids (render/LeafTable.h): for every cell of a box that does not start
// on a leaf boundary, over leaves, leaf-sized and larger tiles, and background, the leaf table
// gives the tree's own values at the cell's eight voxels, in the cell order.
TEST(Render, LeafTablesReadTheTreesValues)
{
    openvdb::initialize();
    openvdb::FloatTree tree(0.25f);
    tree.fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(7)), 0.5f, true);       // one leaf-sized tile
    tree.fill(openvdb::CoordBBox(openvdb::Coord(128, 0, 0), openvdb::Coord(255, 127, 127)), 0.75f, true); // an internal tile
    std::uint32_t h = 12345;
    auto next = [&] { h = h * 1664525u + 1013904223u; return float(h >> 8) / float(1 << 24); };
    for (int i = 0; i < 3000; ++i) {
        const openvdb::Coord c(int(next() * 60) - 20, int(next() * 50) - 15, int(next() * 50) - 25);
        if (c.x() >= 0 && c.x() <= 7 && c.y() >= 0 && c.y() <= 7 && c.z() >= 0 && c.z() <= 7) continue;
        tree.setValueOn(c, next());
    }
    const openvdb::CoordBBox box(openvdb::Coord(-13, -7, -21), openvdb::Coord(134, 25, 18));
    const detail::LeafLayout layout(box);
    const detail::LeafTable<float> table(tree, layout);
    EXPECT_GT(table.leafBlocks(), 10u);
    EXPECT_LT(table.leafBlocks(), layout.blockCount());
    std::size_t cells = 0, bad = 0;
    openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(tree);
    for (int x = box.min().x(); x < box.max().x(); ++x)
        for (int y = box.min().y(); y < box.max().y(); ++y)
            for (int z = box.min().z(); z < box.max().z(); ++z) {
                const int u[3] = {x - layout.min().x(), y - layout.min().y(), z - layout.min().z()};
                float v[8];
                table.read(layout.cell(u[0], u[1], u[2]), v);
                for (int k = 0; k < 8; ++k) {
                    const float want = acc.getValue(openvdb::Coord(x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1)));
                    bad += std::memcmp(&v[k], &want, 4) != 0;
                }
                ++cells;
            }
    EXPECT_EQ(cells, std::size_t(147) * 32 * 39);
    EXPECT_EQ(bad, 0u);
}

// Density and halo are copied dense when their leaves fill half the box, else read through the
// leaf tables: a diagonal line (few leaves) and the same line with every other voxel of its box
// set active at 0 (leaves everywhere; the same values, the same box) render the same bits, lit,
// coloured and with halos.
TEST(Render, DenseCopiesAndLeafTablesRenderAlike)
{
    const Vec3d dir = Vec3d(1, 1, 1) / std::sqrt(3.0);
    const openvdb::Coord lo(-16), hi(16);
    auto d = makeScalar("density", 1.0, lo, hi, [&](const Vec3d& p) { return 1.0 - lineDistance(p, Vec3d(0), dir) / 1.5; });
    auto h = makeScalar("halo", 1.0, lo, hi, [&](const Vec3d& p) { return 1.0 - lineDistance(p, Vec3d(0), dir) / 3.0; });
    RenderVolume thin;
    thin.density = d;
    thin.halo = h;
    thin.tangent = makeConstVec("tangent", *h, Vec3d(1, 1, 1));
    thin.color = makeConstVec("color", *h, Vec3d(0.9, 0.5, 0.2));
    RenderVolume full = thin;
    auto filled = d->deepCopy();
    const openvdb::CoordBBox box = d->evalActiveVoxelBoundingBox();
    for (auto ijk = box.begin(); ijk; ++ijk)
        if (!filled->tree().isValueOn(*ijk)) filled->tree().setValueOn(*ijk, 0.0f);
    full.density = filled;
    ASSERT_EQ(filled->evalActiveVoxelBoundingBox(), box);
    CameraSettings cs;
    cs.azimuth = 21;
    cs.elevation = 17;
    cs.width = 48;
    cs.height = 40;
    const HaloRaycaster a(thin, RenderSettings{}), b(full, RenderSettings{});
    EXPECT_FALSE(a.denseCopies());
    EXPECT_TRUE(b.denseCopies());
    expectSameImage(a, b, cs, 10.0);
}

TEST(Render, RefusesBadInput)
{
    RenderVolume vol;
    EXPECT_THROW(HaloRaycaster(vol, RenderSettings{}), InputError);
    vol.density = openvdb::FloatGrid::create(0.0f);
    EXPECT_THROW(HaloRaycaster(vol, RenderSettings{}), InputError) << "no active voxels";
    RenderSettings s;
    s.densityScale = -1;
    EXPECT_THROW(s.validate(), InputError);
    CameraSettings cs;
    cs.width = 0;
    EXPECT_THROW(cs.validate(), InputError);
    cs = CameraSettings{};
    cs.elevation = 91;
    EXPECT_THROW(cs.validate(), InputError);
}

// ---- image output -----------------------------------------------------------------------------

namespace {

/// Image and render-job tests write into a scratch directory of their own, `mDir`.
class ImageIO : public lictest::TempDirTest {};
class RenderJob : public lictest::TempDirTest {};

lic::Image ramp()
{
    lic::Image img(4, 2);
    const float values[4] = {0.0f, 0.18f, 1.0f, 4.0f};
    for (int x = 0; x < 4; ++x)
        for (int y = 0; y < 2; ++y) {
            float* p = img.pixel(x, y);
            p[0] = p[1] = p[2] = values[x];
            p[3] = 1.0f;
        }
    img.pixel(0, 1)[0] = 0.5f; // one coloured pixel
    return img;
}

} // namespace

TEST_F(ImageIO, ExrIsSceneLinearAndRoundTrips)
{
    const fs::path dir = mDir;
    const std::string path = (dir / "a.exr").string();
    const lic::Image img = ramp();
    vdbexport::writeImageAtomic(path, img, {});
    std::string cs;
    const lic::Image back = vdbexport::readImage(path, &cs);
    ASSERT_EQ(back.width, 4);
    ASSERT_EQ(back.height, 2);
    for (std::size_t i = 0; i < img.rgba.size(); ++i) EXPECT_EQ(back.rgba[i], img.rgba[i]) << i;
    EXPECT_EQ(cs, "lin_rec709_scene"); // OIIO 2.4 reads "Linear", 3.x "lin_rec709_scene"
    EXPECT_FALSE(fs::exists(path + ".tmp-" + std::to_string(::getpid())));
}

// OIIO 2.4 and 3.x name the same colour spaces differently; readImage reports one name.
TEST_F(ImageIO, ColorSpaceNamesOfEveryOiioAreOne)
{
    for (const char* name : {"Linear", "linear", "lin_rec709", "lin_srgb", "lin_rec709_scene"})
        EXPECT_EQ(vdbexport::canonicalColorSpace(name), "lin_rec709_scene") << name;
    for (const char* name : {"sRGB", "srgb", "srgb_rec709_scene"})
        EXPECT_EQ(vdbexport::canonicalColorSpace(name), "srgb_rec709_scene") << name;
    EXPECT_EQ(vdbexport::canonicalColorSpace("ACEScg"), "ACEScg");
    EXPECT_EQ(vdbexport::canonicalColorSpace(""), "");
}

TEST_F(ImageIO, PngGoesThroughTheOcioDisplayTransform)
{
    const fs::path dir = mDir;
    vdbexport::DisplayTransform t;
    t.config = vdbexport::findOcioConfig();
    ASSERT_TRUE(fs::exists(t.config));
    const lic::Image img = ramp();
    // Standard: sRGB encoding of the clipped value.
    const std::vector<float> disp = vdbexport::toDisplay(img, t);
    EXPECT_NEAR(disp[0], 0.0f, 1e-4);
    EXPECT_NEAR(disp[3], 0.46135f, 2e-3); // sRGB(0.18)
    EXPECT_NEAR(disp[6], 1.0f, 1e-4);
    EXPECT_NEAR(disp[9], 1.0f, 1e-4); // clipped
    EXPECT_NEAR(disp[12], 0.73536f, 2e-3); // sRGB(0.5) in the red of pixel (0, 1)
    const std::string png = (dir / "a.png").string();
    vdbexport::writeImageAtomic(png, img, t);
    const lic::Image back = vdbexport::readImage(png);
    EXPECT_NEAR(back.pixel(1, 0)[0], std::round(0.46135f * 255.0f) / 255.0f, 1e-6);
    EXPECT_NEAR(back.pixel(3, 0)[0], 1.0f, 1e-6);
    EXPECT_NEAR(back.pixel(0, 1)[0], std::round(0.73536f * 255.0f) / 255.0f, 1e-6);
    EXPECT_NEAR(back.pixel(0, 1)[1], 0.0f, 1e-6);
    // Filmic: a tone curve (mid grey darker than Standard, highlights below 1, 4.0 not clipped).
    t.view = vdbexport::viewFromFlag("filmic");
    const std::vector<float> film = vdbexport::toDisplay(img, t);
    EXPECT_NEAR(film[3], 0.41f, 0.01f);
    EXPECT_NEAR(film[6], 0.84f, 0.01f);
    EXPECT_GT(film[9], film[6]);
    EXPECT_LT(film[9], 1.0f);
    EXPECT_THROW(vdbexport::viewFromFlag("agx"), InputError);
    vdbexport::DisplayTransform bad = t;
    bad.view = "Nope";
    EXPECT_THROW(vdbexport::toDisplay(img, bad), InputError);
    EXPECT_THROW(vdbexport::findOcioConfig((dir / "missing.ocio").string()), InputError);
}

TEST_F(ImageIO, AnimatedGifAndFailuresLeaveNoFile)
{
    const fs::path dir = mDir;
    vdbexport::DisplayTransform t;
    t.config = vdbexport::findOcioConfig();
    const std::string gif = (dir / "a.gif").string();
    vdbexport::writeGifAtomic(gif, {ramp(), ramp(), ramp()}, t, 10.0);
    ASSERT_TRUE(fs::exists(gif));
    const lic::Image first = vdbexport::readImage(gif);
    EXPECT_EQ(first.width, 4);
    EXPECT_THROW(vdbexport::writeImageAtomic((dir / "a.bmpx").string(), ramp(), t), InputError);
    EXPECT_THROW(vdbexport::writeImageAtomic((dir / "no" / "a.png").string(), ramp(), t), InputError);
    EXPECT_FALSE(fs::exists(dir / "a.bmpx"));
}

TEST_F(RenderJob, SequenceAndImageNames)
{
    EXPECT_EQ(vdbexport::imageFramePath("out/a.png", 1, 1), "out/a.png");
    EXPECT_EQ(vdbexport::imageFramePath("out/a.png", 3, 24), "out/a_0003.png");
    EXPECT_EQ(vdbexport::imageFramePath("a.exr", 12, 24), "a_0012.exr");
    const fs::path dir = mDir;
    for (int f = 1; f <= 3; ++f) std::ofstream(dir / ("s_000" + std::to_string(f) + ".vdb")) << "x";
    const auto files = vdbexport::renderInputs((dir / "s_0001.vdb").string(), 3);
    ASSERT_EQ(files.size(), 3u);
    EXPECT_EQ(files[2], (dir / "s_0003.vdb").string());
    EXPECT_EQ(vdbexport::renderInputs((dir / "s.vdb").string(), 2)[1], (dir / "s_0002.vdb").string());
    EXPECT_THROW(vdbexport::renderInputs((dir / "s_0001.vdb").string(), 4), InputError);
    std::ofstream(dir / "m.json") << R"({"files": ["s_0001.vdb", "s_0002.vdb"]})";
    const auto fromManifest = vdbexport::renderInputs((dir / "m.json").string(), 0);
    ASSERT_EQ(fromManifest.size(), 2u);
    EXPECT_EQ(fromManifest[1], (dir / "s_0002.vdb").string());
    EXPECT_THROW(vdbexport::renderInputs((dir / "m.json").string(), 3), InputError);
}

TEST_F(RenderJob, CameraJsonReproducesTheCameraInBlenderTerms)
{
    CameraSettings cs;
    cs.azimuth = 35;
    cs.elevation = 25;
    cs.width = 64;
    cs.height = 48;
    const Camera c = makeCamera(cs, openvdb::BBoxd(Vec3d(-1), Vec3d(2)));
    const auto j = vdbexport::cameraJson(c);
    EXPECT_EQ(j["projection"], "perspective");
    EXPECT_NEAR(j["fov_y_degrees"].get<double>(), 30.0, 1e-12);
    // Rebuild the rotation from Blender's XYZ Euler (R = Rz·Ry·Rx) and compare with the frame.
    const double ex = j["blender"]["rotation_euler"][0], ey = j["blender"]["rotation_euler"][1],
                 ez = j["blender"]["rotation_euler"][2];
    const double cx = std::cos(ex), sx = std::sin(ex), cy = std::cos(ey), sy = std::sin(ey), cz = std::cos(ez),
                 sz = std::sin(ez);
    const openvdb::Mat3d Rx(1.0, 0.0, 0.0, 0.0, cx, -sx, 0.0, sx, cx);
    const openvdb::Mat3d Ry(cy, 0.0, sy, 0.0, 1.0, 0.0, -sy, 0.0, cy);
    const openvdb::Mat3d Rz(cz, -sz, 0.0, sz, cz, 0.0, 0.0, 0.0, 1.0);
    const openvdb::Mat3d R = Rz * Ry * Rx; // row-major, column-vector convention
    for (int row = 0; row < 3; ++row) {
        EXPECT_NEAR(R(row, 0), c.right[row], 1e-9);
        EXPECT_NEAR(R(row, 1), c.up[row], 1e-9);
        EXPECT_NEAR(R(row, 2), -c.forward[row], 1e-9);
        EXPECT_NEAR(j["blender"]["matrix_world"][row][3].get<double>(), c.position[row], 1e-12);
    }
}

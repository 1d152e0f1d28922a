#include "lic/engine/Splat.h"

#include "lic/engine/Kernels.h"
#include "lic/texture/Noise.h"

#include "lic/util/Error.h"
#include "lic/util/Parallel.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <array>
#include <map>
#include <memory>
#include <optional>

namespace lic {

namespace {

/// Kernel weight of window sample i (box: i in [−n, n]; exp: i in [0, n], c^i).
struct Window
{
    int lo, hi;        // sample offsets
    bool exp;
    double decay;
    std::vector<double> weights; // c^i for i = lo … hi (exp), else empty
    double weight(int i) const { return exp ? weights[std::size_t(i - lo)] : 1.0; }
    double total() const
    {
        double t = 0;
        for (int i = lo; i <= hi; ++i) t += weight(i);
        return t;
    }
};

/// The ripple normalisation Σ w_i e^{iθi} / Σ w_i over window samples i0 … i1 (as Re, Im). Box
/// over a whole window: 0 up to rounding, returned as exactly 0 (the period is the window).
std::array<double, 2> rippleNorm(const Window& win, double theta, int i0, int i1)
{
    if (!win.exp && i0 == win.lo && i1 == win.hi) return {0.0, 0.0};
    double nr = 0, ni = 0, total = 0;
    for (int i = i0; i <= i1; ++i) {
        const double w = win.weight(i);
        nr += w * std::cos(theta * double(i));
        ni += w * std::sin(theta * double(i));
        total += w;
    }
    return {nr / total, ni / total};
}

Window windowOf(const LicSettings& s)
{
    const int n = s.halfSamples();
    const bool exp = s.kernel == KernelType::Exp;
    Window w{exp ? 0 : -n, n, exp, s.decay, {}};
    if (exp)
        for (int i = w.lo; i <= w.hi; ++i) w.weights.push_back(std::pow(s.decay, double(i)));
    return w;
}

} // namespace

SplatTables::SplatTables(const std::vector<double>& radii, const LicSettings& settings)
    : mRadii(radii)
    , mH(settings.step)
    , mDecay(settings.decay)
    , mTheta(detail::rippleStep(settings))
    , mExp(settings.kernel == KernelType::Exp)
    , mRipple(settings.ripple)
    , mC(int(radii.size()))
    , mParts(settings.ripple ? 3 * int(radii.size()) : int(radii.size()))
    , mReach(0)
{
    const double h = settings.step;
    const Window win = windowOf(settings);
    for (double r : radii) mReach = std::max(mReach, r + 0.5 * std::min(1.0, r));
    mTauMin = -(double(win.hi) * h + mReach);
    mTauMax = -double(win.lo) * h + mReach;
    mDTau = h / 4.0;
    mDD = 1.0 / 16.0;
    mNTau = int(std::ceil((mTauMax - mTauMin) / mDTau)) + 1;
    mND = int(std::ceil(mReach / mDD)) + 2;
    mInvDTau = exactInverse(mDTau);
    mInvDD = exactInverse(mDD);
    mTable.assign(std::size_t(mNTau) * std::size_t(mND) * std::size_t(mParts), 0.0f);
    if (mExp) mWeights = win.weights; // i = 0 … n
    const double total = win.total();
    const double theta = detail::rippleStep(settings);
    tbb::parallel_for(0, mNTau, [&](int t) {
        const double tau = mTauMin + double(t) * mDTau;
        // Only the window samples within reach of the spot contribute.
        const int i0 = std::max(win.lo, int(std::ceil((-mReach - tau) / h)));
        const int i1 = std::min(win.hi, int(std::floor((mReach - tau) / h)));
        for (int di = 0; di < mND; ++di) {
            const double d = double(di) * mDD;
            float* out = &mTable[(std::size_t(t) * std::size_t(mND) + std::size_t(di)) * std::size_t(mParts)];
            for (int c = 0; c < mC; ++c) {
                double a = 0, zr = 0, zi = 0;
                for (int i = i0; i <= i1; ++i) {
                    const double along = tau + double(i) * h;
                    double slope;
                    const double f = spotProfile(std::sqrt(d * d + along * along), radii[std::size_t(c)], slope);
                    if (f == 0.0) continue;
                    a += win.weight(i) * f;
                    if (settings.ripple) {
                        zr += win.weight(i) * f * std::cos(theta * double(i));
                        zi += win.weight(i) * f * std::sin(theta * double(i));
                    }
                }
                out[c] = float(a / total);
                if (settings.ripple) {
                    out[mC + c] = float(zr / total);
                    out[2 * mC + c] = float(zi / total);
                }
            }
        }
    });
}

namespace {

/// out[p] += the four corners' weighted sum, for p < P known at compile time (no aliasing checks,
/// no remainder loop): the same operations in the same order as the general loop below.
template<std::size_t P>
void addCorners(const float* c00, const float* c01, const float* c10, const float* c11, float w00, float w01,
                float w10, float w11, float* __restrict out)
{
    for (std::size_t p = 0; p < P; ++p) out[p] += w00 * c00[p] + w01 * c01[p] + w10 * c10[p] + w11 * c11[p];
}

} // namespace

[[gnu::always_inline]] inline SplatTables::Cell SplatTables::cell(double tau, double d) const
{
    Cell c;
    if (!(tau >= mTauMin && tau <= mTauMax && d < mReach)) return c;
    const double ft = mInvDTau != 0 ? (tau - mTauMin) * mInvDTau : (tau - mTauMin) / mDTau;
    const double fd = mInvDD != 0 ? d * mInvDD : d / mDD;
    const int t0 = std::min(int(ft), mNTau - 2), d0 = std::min(int(fd), mND - 2);
    c.wt = float(ft - t0);
    c.wd = float(fd - d0);
    c.c00 = &mTable[(std::size_t(t0) * std::size_t(mND) + std::size_t(d0)) * std::size_t(mParts)];
    return c;
}

void SplatTables::prefetch(double tau, double d) const
{
    const Cell c = cell(tau, d);
    if (!c.c00) return;
    const std::size_t P = std::size_t(mParts), row = std::size_t(mND) * P;
    // The two corners of each τ row lie side by side: their first and last floats.
    __builtin_prefetch(c.c00);
    __builtin_prefetch(c.c00 + 2 * P - 1);
    __builtin_prefetch(c.c00 + row);
    __builtin_prefetch(c.c00 + row + 2 * P - 1);
}

double SplatTables::exactInverse(double step)
{
    int e = 0;
    return std::frexp(step, &e) == 0.5 ? 1.0 / step : 0.0;
}

void SplatTables::add(double tau, double d, float a, float* out) const
{
    const Cell at = cell(tau, d);
    if (!at.c00) return;
    const float wt = at.wt, wd = at.wd;
    const std::size_t P = std::size_t(mParts), row = std::size_t(mND) * P;
    const float* c00 = at.c00;
    const float* c01 = c00 + P;
    const float* c10 = c00 + row;
    const float* c11 = c10 + P;
    const float w00 = a * (1 - wt) * (1 - wd), w01 = a * (1 - wt) * wd, w10 = a * wt * (1 - wd), w11 = a * wt * wd;
    // The part counts of 1–4 widths with their halos (2, 4, 6, 8), and of one width alone.
    switch (P) {
    case 1: return addCorners<1>(c00, c01, c10, c11, w00, w01, w10, w11, out);
    case 2: return addCorners<2>(c00, c01, c10, c11, w00, w01, w10, w11, out);
    case 4: return addCorners<4>(c00, c01, c10, c11, w00, w01, w10, w11, out);
    case 6: return addCorners<6>(c00, c01, c10, c11, w00, w01, w10, w11, out);
    case 8: return addCorners<8>(c00, c01, c10, c11, w00, w01, w10, w11, out);
    default:
        for (std::size_t p = 0; p < P; ++p) out[p] += w00 * c00[p] + w01 * c01[p] + w10 * c10[p] + w11 * c11[p];
    }
}

void SplatTables::addDirect(double tau, double d, float a, int i0, int i1, double weight, float* out) const
{
    i0 = std::max(i0, int(std::ceil((-mReach - tau) / mH)));
    i1 = std::min(i1, int(std::floor((mReach - tau) / mH)));
    for (int i = i0; i <= i1; ++i) {
        const double along = tau + double(i) * mH, r = std::sqrt(d * d + along * along);
        const double w = (mExp ? mWeights[std::size_t(i)] : 1.0) * double(a) / weight;
        for (int c = 0; c < mC; ++c) {
            double slope;
            const double f = spotProfile(r, mRadii[std::size_t(c)], slope);
            if (f == 0.0) continue;
            out[c] += float(w * f);
            if (mRipple) {
                out[mC + c] += float(w * f * std::cos(mTheta * double(i)));
                out[2 * mC + c] += float(w * f * std::sin(mTheta * double(i)));
            }
        }
    }
}

CometTables::CometTables(const SplatTables& still, const LicSettings& settings, double spacing)
    : mN(settings.comets)
    , mC(still.channels())
    , mP(spacing)
    , mTauMin(still.tauMin() - spacing)
    , mTauMax(still.tauMax() + spacing)
    , mReach(still.reach())
    , mDTau(settings.step / 4.0)
    , mDD(1.0 / 16.0)
{
    if (mN < 2) throw InputError("comet tables need at least 2 frames");
    mNTau = int(std::ceil((mTauMax - mTauMin) / mDTau)) + 1;
    mND = int(std::ceil(mReach / mDD)) + 2;
    for (int g = 0; g < mN; ++g)
        for (int m = 0; m < 2; ++m) mFade.push_back(cometFade(copyArc(g, m), mP));
    const std::size_t row = std::size_t(mN) * std::size_t(mC);
    mTable.assign(std::size_t(mNTau) * std::size_t(mND) * row, 0.0f);
    tbb::parallel_for(0, mNTau, [&](int t) {
        const double tau = mTauMin + double(t) * mDTau;
        std::vector<float> parts(static_cast<std::size_t>(mC), 0.0f);
        for (int di = 0; di < mND; ++di) {
            const double d = double(di) * mDD;
            float* out = &mTable[(std::size_t(t) * std::size_t(mND) + std::size_t(di)) * row];
            for (int g = 0; g < mN; ++g) {
                std::fill(parts.begin(), parts.end(), 0.0f);
                for (int m = 0; m < 2; ++m) still.add(tau - copyArc(g, m), d, float(copyFade(g, m)), parts.data());
                std::copy(parts.begin(), parts.end(), out + std::size_t(g) * std::size_t(mC));
            }
        }
    });
}

CometTables::Corners CometTables::corners(double tau, double d, float a) const
{
    Corners c;
    if (!(tau >= mTauMin && tau <= mTauMax && d < mReach)) return c;
    const double ft = (tau - mTauMin) / mDTau, fd = d / mDD;
    const int t0 = std::min(int(ft), mNTau - 2), d0 = std::min(int(fd), mND - 2);
    const float wt = float(ft - t0), wd = float(fd - d0);
    const std::size_t P = std::size_t(mN) * std::size_t(mC), row = std::size_t(mND) * P;
    c.p[0] = &mTable[(std::size_t(t0) * std::size_t(mND) + std::size_t(d0)) * P];
    c.p[1] = c.p[0] + P;
    c.p[2] = c.p[0] + row;
    c.p[3] = c.p[2] + P;
    c.w = {a * (1 - wt) * (1 - wd), a * (1 - wt) * wd, a * wt * (1 - wd), a * wt * wd};
    return c;
}

void CometTables::add(double tau, double d, float a, int phase, float* out) const
{
    const Corners k = corners(tau, d, a);
    if (!k.p[0]) return;
    // Frame f shows phase g = (f + phase) mod N: walk the phases from `phase`, frames from 0.
    const std::size_t C = std::size_t(mC);
    std::size_t g = std::size_t(phase);
    for (std::size_t f = 0; f < std::size_t(mN); ++f, g = (g + 1 == std::size_t(mN) ? 0 : g + 1)) {
        const std::size_t o = g * C;
        float* dst = out + f * C;
        for (std::size_t c = 0; c < C; ++c)
            dst[c] += k.w[0] * k.p[0][o + c] + k.w[1] * k.p[1][o + c] + k.w[2] * k.p[2][o + c] + k.w[3] * k.p[3][o + c];
    }
}

void CometTables::addPhase(double tau, double d, float a, int g, float* out) const
{
    const Corners k = corners(tau, d, a);
    if (!k.p[0]) return;
    const std::size_t C = std::size_t(mC), o = std::size_t(g) * C;
    for (std::size_t c = 0; c < C; ++c)
        out[c] += k.w[0] * k.p[0][o + c] + k.w[1] * k.p[1][o + c] + k.w[2] * k.p[2][o + c] + k.w[3] * k.p[3][o + c];
}


namespace {

/// Column-major 3×3 in output index units: G_j maps an offset from the line at sample j back to
/// the offset it came from at the spot (the inverse of the flow map's Jacobian along the line).
using Xform = std::array<float, 9>;

/// One spot's streamline, output-index positions every h.
struct SpotLine
{
    // Made by the thread that traced the line (no serial packing pass afterwards).
    std::vector<openvdb::Vec3f> points;   // the samples
    std::vector<openvdb::Vec3f> tangents; // unit direction at each sample
    std::vector<Xform> xforms;            // the transport back to the spot at each sample
    int count = 0;           // samples
    int centre = 0;          // index of the spot itself among them
    double endBack = -1e300; // arc of a natural end upstream (a wall or critical point), else −∞
    double endFwd = 1e300;   // … downstream, else +∞
    openvdb::Vec3f lo, hi;   // bounds of the samples
    openvdb::Vec3f tangent;  // unit flow direction at the spot (output index space)
    int phase = 0;           // comet loops: the spot's phase (cometPhase)
};

/// Transports of offsets along one spot line: M(s) solves dM/ds = J_u M, M(0) = I, where J_u is
/// the Jacobian of the unit flow direction (world units; arc s in world units), so an offset δ at
/// the spot becomes M(s)δ at arc s. Returns G_j = A⁻¹ M(s_j)⁻¹ A per sample, A = the output
/// index→world linear map.
void transports(const VelocityField& field, const OutputDomain& domain, const std::vector<openvdb::Vec3f>& pts,
                int centre, double hWorld, std::vector<Xform>& out)
{
    using openvdb::Mat3d;
    const openvdb::Mat4d& iw = domain.map().indexToWorld; // row-vector layout: w = q·iw
    Mat3d A; // column convention: w = A q
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) A[a][b] = iw[b][a];
    const Mat3d Ainv = A.inverse();
    const int n = int(pts.size());
    std::vector<Mat3d> J(std::size_t(n), Mat3d::zero());
    for (int j = 0; j < n; ++j) {
        openvdb::Vec3d v;
        Mat3d dv;
        if (!field.sampleGradient(domain.map().toWorld(openvdb::Vec3d(pts[std::size_t(j)])), v, dv)) continue;
        const double len = v.length();
        if (!(len > 0)) continue;
        const openvdb::Vec3d u = v / len;
        Mat3d P = Mat3d::identity(); // projector off u
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) P[a][b] -= u[a] * u[b];
        J[std::size_t(j)] = (P * dv) * (1.0 / len);
    }
    auto step = [&](const Mat3d& Jm, double hs) { // I + hs J + hs²/2 J²
        return Mat3d::identity() + Jm * hs + (Jm * Jm) * (0.5 * hs * hs);
    };
    std::vector<Mat3d> M(std::size_t(n), Mat3d::identity());
    for (int j = centre + 1; j < n; ++j) M[std::size_t(j)] = step(J[std::size_t(j - 1)], hWorld) * M[std::size_t(j - 1)];
    for (int j = centre - 1; j >= 0; --j) M[std::size_t(j)] = step(J[std::size_t(j + 1)], -hWorld) * M[std::size_t(j + 1)];
    out.resize(std::size_t(n));
    for (int j = 0; j < n; ++j) {
        // M⁻¹ as Mat3::inverse() computes it (adjoint / determinant), but without its throw: that
        // determinant (expanded by column) can be exactly 0 where det() (by row) is not, for a
        // transport squeezed to nothing whose entries are large.
        const Mat3d& Mj = M[std::size_t(j)];
        const Mat3d adj = Mj.adjoint();
        const double det = Mj.det(), detInv = adj(0, 0) * Mj(0, 0) + adj(0, 1) * Mj(1, 0) + adj(0, 2) * Mj(2, 0);
        Mat3d G = Mat3d::identity();
        if (std::abs(det) > 1e-12 && detInv != 0.0 && std::isfinite(detInv)) G = Ainv * (adj * (1.0 / detInv)) * A;
        else G = Mat3d::identity() * 1e6; // lines squeezed to nothing: push every voxel out of reach
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) out[std::size_t(j)][std::size_t(b * 3 + a)] = float(G[a][b]);
    }
}

/// A float array that grows without zeroing: the splat writes every part it reads first (a block's
/// accumulators when a footprint first reaches it, a touched block's hand-over), and a comet
/// loop's brick × N·C floats (48 MiB for a 64³ brick at 24 frames) would otherwise be zeroed and
/// faulted in whole.
class GrowingBuffer
{
public:
    void reserve(std::size_t n)
    {
        if (n <= mSize) return;
        mData = std::make_unique_for_overwrite<float[]>(n);
        mSize = n;
    }
    float* data() { return mData.get(); }
    const float* data() const { return mData.get(); }

private:
    std::unique_ptr<float[]> mData;
    std::size_t mSize = 0;
};

/// Per-thread buffers of the splat: the brick's accumulators and the per-spot rasterisation state.
struct SplatScratch
{
    GrowingBuffer acc;                 // voxel × channels (a block's set when it turns dirty)
    std::vector<float> nearest;        // voxel: distance to the nearest spot line so far (loops)
    std::vector<std::uint8_t> dirty;   // local block: accumulators in use
    std::vector<std::uint32_t> stamp;  // voxel: spot generation of best/arc
    std::vector<float> best, arc;      // voxel: squared distance and arc of the nearest line point
    std::vector<openvdb::Vec3f> offset;// voxel: its offset from that point (output index units)
    std::vector<std::int32_t> foot;    // voxel: the line sample nearest that point
    std::vector<std::int64_t> touched; // voxels reached by the current spot
    /// A touched voxel within the footprint's support: where its window lies on the spot's line.
    struct Foot
    {
        std::size_t li;
        double tau, d;
    };
    std::vector<Foot> feet;
    GrowingBuffer out;                 // the brick's channels, handed to the sink (touched blocks)
    std::vector<std::uint8_t> blockTouched;
    std::vector<float> parts;
    BrickIndex index;
    std::uint32_t generation = 0;
    LicStats stats;
};

} // namespace

namespace {

/// Rasterise around every kCoarse-th sample of a spot's line (2 voxels apart at h = ½).
constexpr int kCoarse = 4;

/// Half-width along the line of the slab around a coarse sample that the rasteriser covers.
double slabHalf(double h) { return 0.5 * kCoarse * h + 0.5; }

bool naturalEnd(StopReason w) { return w == StopReason::Boundary || w == StopReason::ZeroVelocity; }

/// One splat convolution: the spots' lines (traced once), which spots reach which brick, and each
/// brick's deposits.
class SplatRun
{
public:
    SplatRun(const VelocityField& field, const OutputDomain& domain, const BrickLayout& layout, const SpotSet& spots,
             const std::vector<double>& channelRadii, const LicSettings& settings)
        : mField(field)
        , mDomain(domain)
        , mLayout(layout)
        , mSpots(spots)
        , mSettings(settings)
        , mTables(channelRadii, settings)
        , mC(int(channelRadii.size()))
        , mK(settings.outputChannels(int(channelRadii.size())))
        , mH(settings.step)
        , mWin(windowOf(settings))
        , mWinTotal(mWin.total())
        , mTheta(detail::rippleStep(settings))
        , mWholeNorm(rippleNorm(mWin, mTheta, mWin.lo, mWin.hi)) // box: (0, 0)
        , mReach(mTables.reach())
        , mRho(std::sqrt(mReach * mReach + slabHalf(mH) * slabHalf(mH)) + 0.25)
    {
        if (settings.comets > 0)
            mComets.emplace(mTables, settings,
                            cometSpacing(settings, *std::max_element(channelRadii.begin(), channelRadii.end())));
        mTauMin = mComets ? mComets->tauMin() : mTables.tauMin();
        mTauMax = mComets ? mComets->tauMax() : mTables.tauMax();
    }

    /// 1. Trace every spot's streamline over the kernel's support (independent per spot).
    std::uint64_t traceLines();
    /// 2. Which spots reach which brick (in spot order), per brick position in the layout.
    std::vector<std::vector<std::uint32_t>> spotsPerBrick() const;
    /// 3. Deposit the footprints of `spotIds` into the brick's own voxels; hand it to `sink`.
    void brick(const Brick& brick, const std::vector<std::uint32_t>& spotIds, SplatScratch& sc,
               const BrickSink& sink) const;

private:
    void traceLine(std::size_t s, std::vector<openvdb::Vec3f>& back, std::vector<openvdb::Vec3d>& scratch,
                   std::vector<openvdb::Vec3f>& pts, std::vector<Xform>& xf);
    void prepareBrick(const Brick& brick, SplatScratch& sc) const;
    /// The nearest point of spot line L to every voxel of the brick within reach of it.
    void nearestPoints(const SpotLine& L, const Brick& brick, SplatScratch& sc) const;
    /// Add the spot's footprint at every voxel nearestPoints() found; returns the deposits.
    std::uint64_t depositSpot(const SpotLine& L, float weight, SplatScratch& sc) const;
    /// Comet loops: every frame's footprint of the spot's comet train at voxel li.
    void depositComets(const SpotLine& L, float weight, double tau, double d, SplatScratch& sc, std::size_t li) const;
    void handOver(const Brick& brick, SplatScratch& sc, const BrickSink& sink) const;
    /// Clear the accumulators of voxel li's block the first time a spot reaches it.
    void startBlock(std::size_t li, SplatScratch& sc) const;

    const VelocityField& mField;
    const OutputDomain& mDomain;
    const BrickLayout& mLayout;
    const SpotSet& mSpots;
    const LicSettings& mSettings;
    const SplatTables mTables;
    std::optional<CometTables> mComets;
    double mTauMin = 0, mTauMax = 0; // arcs from the spot a voxel's foot point can have and count
    const int mC, mK;
    const double mH;
    const Window mWin;
    const double mWinTotal, mTheta;
    const std::array<double, 2> mWholeNorm;
    const double mReach, mRho;
    TraceSettings mTrace; // along a spot's line: over the kernel's support each way
    int mStride = 1;
    std::vector<SpotLine> mLines;
};

std::uint64_t SplatRun::traceLines()
{
    const std::size_t n = mSpots.centers.size();
    mTrace = detail::traceSettings(mField, mDomain, mSettings);
    mTrace.maxSamples = int(std::ceil((std::max(-mTauMin, mTauMax) + 1.0) / mH));
    mStride = detail::integrationStride(mDomain, mSettings);
    mLines.assign(n, SpotLine{});
    tbb::enumerable_thread_specific<std::pair<std::vector<openvdb::Vec3f>, std::vector<openvdb::Vec3d>>> tls;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
        auto& [back, scratch] = tls.local();
        for (std::size_t s = r.begin(); s != r.end(); ++s) {
            SpotLine& L = mLines[s];
            traceLine(s, back, scratch, L.points, L.xforms);
            // Unit direction at every sample (central differences; one-sided at the ends).
            const std::vector<openvdb::Vec3f>& p = L.points;
            L.tangents.resize(p.size());
            for (int j = 0; j < int(p.size()); ++j) {
                openvdb::Vec3f t = p[std::size_t(std::min(int(p.size()) - 1, j + 1))] - p[std::size_t(std::max(0, j - 1))];
                const float tl = t.length();
                L.tangents[std::size_t(j)] = tl > 0 ? t / tl : openvdb::Vec3f(0.0f);
            }
        }
    });
    std::uint64_t samples = 0;
    for (std::size_t s = 0; s < n; ++s) {
        samples += std::uint64_t(mLines[s].count);
        if (mComets) mLines[s].phase = cometPhase(mSpots.centers[s], mComets->frames());
    }
    return samples;
}

void SplatRun::traceLine(std::size_t s, std::vector<openvdb::Vec3f>& back, std::vector<openvdb::Vec3d>& scratch,
                         std::vector<openvdb::Vec3f>& pts, std::vector<Xform>& xf)
{
    const double h = mH, up = double(mDomain.upsample()), upOff = 0.5 * (up - 1.0);
    const openvdb::Vec3d& c = mSpots.centers[s];
    back.clear();
    pts.clear();
    auto toOut = [&](const openvdb::Vec3d& p) {
        return openvdb::Vec3f(float(p[0] * up + upOff), float(p[1] * up + upOff), float(p[2] * up + upOff));
    };
    const openvdb::Vec3d seedIdx((c[0] - upOff) / up, (c[1] - upOff) / up, (c[2] - upOff) / up);
    const auto [whyB, whyF] = traceIndexPair(
        mField, seedIdx, mTrace, mStride, scratch,
        [&](const openvdb::Vec3d& p) { back.push_back(toOut(p)); return true; },
        [&](const openvdb::Vec3d& p) { pts.push_back(toOut(p)); return true; });
    // Assemble upstream … spot … downstream.
    std::vector<openvdb::Vec3f> all(back.rbegin(), back.rend());
    all.push_back(openvdb::Vec3f(float(c[0]), float(c[1]), float(c[2])));
    all.insert(all.end(), pts.begin(), pts.end());
    SpotLine& L = mLines[s];
    L.count = int(all.size());
    L.centre = int(back.size());
    // The wall (or critical point) lies between the last sample and the next one: take the
    // middle, so a voxel's window is cut where, on average, its own line ends.
    if (naturalEnd(whyB)) L.endBack = -(double(back.size()) + 0.5) * h;
    if (naturalEnd(whyF)) L.endFwd = (double(pts.size()) + 0.5) * h;
    L.lo = L.hi = all.front();
    for (const auto& p : all) {
        L.lo = openvdb::math::minComponent(L.lo, p);
        L.hi = openvdb::math::maxComponent(L.hi, p);
    }
    const int cn = std::min(L.count - 1, L.centre + 1), cp = std::max(0, L.centre - 1);
    L.tangent = all[std::size_t(cn)] - all[std::size_t(cp)];
    if (L.tangent.length() > 0) L.tangent.normalize();
    transports(mField, mDomain, all, L.centre, h * mDomain.voxelSize(), xf);
    pts.swap(all);
}

std::vector<std::vector<std::uint32_t>> SplatRun::spotsPerBrick() const
{
    const int dim = mLayout.dim();
    std::map<openvdb::Coord, std::size_t> brickAt;
    for (std::size_t b = 0; b < mLayout.size(); ++b) {
        const openvdb::Coord& o = mLayout[b].box.min();
        brickAt[openvdb::Coord(detail::floorDiv(o[0], dim), detail::floorDiv(o[1], dim), detail::floorDiv(o[2], dim))] = b;
    }
    std::vector<std::vector<std::uint32_t>> spotsOf(mLayout.size());
    for (std::size_t s = 0; s < mLines.size(); ++s) {
        const SpotLine& L = mLines[s];
        openvdb::Coord lo, hi;
        for (int a = 0; a < 3; ++a) {
            lo[a] = detail::floorDiv(int(std::floor(L.lo[a] - mReach - 1.0)), dim);
            hi[a] = detail::floorDiv(int(std::ceil(L.hi[a] + mReach + 1.0)), dim);
        }
        for (int x = lo[0]; x <= hi[0]; ++x)
            for (int y = lo[1]; y <= hi[1]; ++y)
                for (int z = lo[2]; z <= hi[2]; ++z)
                    if (auto it = brickAt.find(openvdb::Coord(x, y, z)); it != brickAt.end())
                        spotsOf[it->second].push_back(std::uint32_t(s));
    }
    return spotsOf;
}

void SplatRun::prepareBrick(const Brick& brick, SplatScratch& sc) const
{
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    sc.index = BrickIndex(mDomain, brick, mLayout.dim());
    const std::size_t voxels = sc.index.voxels(), blocks = voxels / V;
    sc.acc.reserve(voxels * std::size_t(mK));
    sc.nearest.resize(voxels);
    sc.stamp.resize(voxels, 0);
    sc.best.resize(voxels);
    sc.arc.resize(voxels);
    sc.offset.resize(voxels);
    sc.foot.resize(voxels);
    sc.dirty.assign(blocks, 0);
    sc.parts.resize(std::size_t(mTables.parts()));
}

void SplatRun::brick(const Brick& brick, const std::vector<std::uint32_t>& spotIds, SplatScratch& sc,
                     const BrickSink& sink) const
{
    prepareBrick(brick, sc);
    for (std::uint32_t s : spotIds) {
        if (++sc.generation == 0) { // wrapped: forget every stamp
            std::fill(sc.stamp.begin(), sc.stamp.end(), 0);
            sc.generation = 1;
        }
        sc.touched.clear();
        nearestPoints(mLines[s], brick, sc);
        sc.stats.deposits += depositSpot(mLines[s], mSpots.weights[s], sc);
    }
    handOver(brick, sc, sink);
}

void SplatRun::nearestPoints(const SpotLine& L, const Brick& brick, SplatScratch& sc) const
{
    // The voxel's nearest point on the line, near sample j: the voxel's projection on the local
    // direction at j picks the sample jf, then the distance to the line through P_jf along its
    // direction (samples are h apart, so this is the segment distance to within h²/8). All in
    // float: positions are output index units.
    const openvdb::Vec3f* P = L.points.data();
    const openvdb::Vec3f* T = L.tangents.data();
    const BrickIndex& bi = sc.index;
    const std::uint32_t gen = sc.generation;
    const openvdb::Coord bmin = brick.box.min(), bmax = brick.box.max();
    const double rho = mRho, h = mH;
    for (int j = 0;; j = std::min(j + kCoarse, L.count - 1)) {
        const openvdb::Vec3f c = P[j], dir = T[j];
        const bool end = j == 0 || j == L.count - 1;
        const float slab = 0.5f * float(kCoarse * h) + 0.5f, invH = float(1.0 / h);
        const int x0 = std::max(bmin[0], detail::ceilIndex(c[0] - rho)), x1 = std::min(bmax[0], detail::floorIndex(c[0] + rho));
        for (int x = x0; x <= x1; ++x) {
            const float dx = float(x) - c[0], ry2 = float(rho * rho) - dx * dx;
            if (ry2 < 0) continue;
            const float ry = std::sqrt(ry2);
            const int y0 = std::max(bmin[1], detail::ceilIndex(c[1] - ry)), y1 = std::min(bmax[1], detail::floorIndex(c[1] + ry));
            for (int y = y0; y <= y1; ++y) {
                const float dy = float(y) - c[1], rz2 = ry2 - dy * dy;
                if (rz2 < 0) continue;
                const float rz = std::sqrt(rz2);
                const int z0 = std::max(bmin[2], detail::ceilIndex(c[2] - rz)), z1 = std::min(bmax[2], detail::floorIndex(c[2] + rz));
                const float pxy = dx * dir[0] + dy * dir[1];
                for (int z = z0; z <= z1; ++z) {
                    const float along = pxy + (float(z) - c[2]) * dir[2];
                    if (!end && std::abs(along) > slab) continue;
                    const std::int64_t l = bi.localOf(openvdb::Coord(x, y, z));
                    if (l < 0) continue;
                    const int jf = std::clamp(j + detail::floorIndex(along * invH + 0.5f), 0, L.count - 1);
                    const openvdb::Vec3f w = openvdb::Vec3f(float(x), float(y), float(z)) - P[jf];
                    const float a = w.dot(T[jf]);
                    const float d2 = w.lengthSqr() - a * a;
                    const std::size_t li = std::size_t(l);
                    const bool fresh = sc.stamp[li] != gen;
                    if (fresh || d2 < sc.best[li]) {
                        if (fresh) sc.touched.push_back(l);
                        sc.stamp[li] = gen;
                        sc.best[li] = d2;
                        sc.arc[li] = float(double(jf - L.centre) * h) + a;
                        sc.offset[li] = w - T[jf] * a;
                        sc.foot[li] = jf;
                    }
                }
            }
        }
        if (j == L.count - 1) break;
    }
}

void SplatRun::startBlock(std::size_t li, SplatScratch& sc) const
{
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    const std::size_t lb = li / V, K = std::size_t(mK);
    if (sc.dirty[lb]) return;
    sc.dirty[lb] = 1;
    std::fill_n(sc.acc.data() + lb * V * K, V * K, 0.0f);
    std::fill_n(sc.nearest.begin() + std::ptrdiff_t(lb * V), V, std::numeric_limits<float>::max());
}

void SplatRun::depositComets(const SpotLine& L, float weight, double tau, double d, SplatScratch& sc,
                             std::size_t li) const
{
    const CometTables& ct = *mComets;
    float* acc = sc.acc.data() + li * std::size_t(mK);
    // Lines that run on past every copy's support each way: one lookup gives every frame.
    const double span = ct.spacing() + std::max(-mTables.tauMin(), mTables.tauMax()) + mH;
    if (L.endBack < -span && L.endFwd > span) {
        ct.add(tau, d, weight, L.phase, acc);
        return;
    }
    // A line that ends at a wall or critical point within the train: copies beyond the end do not
    // exist, those approaching it fade out over half a comet (so nothing pops), and the voxel's
    // window is cut at the end as in a still (sums worked out directly).
    const Window& win = mWin;
    const double h = mH, ramp = 0.5 * double(win.hi - win.lo) * h + mReach; // half a comet
    int i0 = win.lo, i1 = win.hi;
    if (L.endBack > -1e299) i0 = std::max(i0, int(std::ceil((L.endBack - tau) / h - 1e-9)));
    if (L.endFwd < 1e299) i1 = std::min(i1, int(std::floor((L.endFwd - tau) / h + 1e-9)));
    if (i1 < i0) return;
    double inside = 0;
    for (int i = i0; i <= i1; ++i) inside += win.weight(i);
    const int N = ct.frames(), C = mC;
    const double reach = mReach, clear = ramp + reach + h;
    const bool whole = i0 == win.lo && i1 == win.hi;
    for (int f = 0; f < N; ++f) {
        const int g = (f + L.phase) % N;
        // Both copies clear of the ends (no fade, no cut): the phase's table entry.
        if (whole && std::min(L.endFwd - ct.copyArc(g, 0), ct.copyArc(g, 1) - L.endBack) >= clear) {
            ct.addPhase(tau, d, weight, g, acc + std::size_t(f) * std::size_t(C));
            continue;
        }
        for (int m = 0; m < 2; ++m) {
            const double a = ct.copyArc(g, m), t = tau - a;
            if (t < mTables.tauMin() || t > mTables.tauMax()) continue;
            const double wall = std::clamp(std::min(L.endFwd - a, a - L.endBack) / ramp, 0.0, 1.0);
            const double amp = ct.copyFade(g, m) * wall;
            if (!(amp > 0)) continue;
            std::fill(sc.parts.begin(), sc.parts.end(), 0.0f);
            // As in a still: a copy within reach of the end is summed directly (part of it lies
            // beyond), others from the table, renormalised to the window's samples inside.
            if (L.endFwd - a < reach + h || a - L.endBack < reach + h)
                mTables.addDirect(t, d, float(double(weight) * amp), i0, i1, inside, sc.parts.data());
            else
                mTables.add(t, d, float(double(weight) * amp * mWinTotal / inside), sc.parts.data());
            for (int c = 0; c < C; ++c) acc[f * C + c] += sc.parts[std::size_t(c)];
        }
    }
}

std::uint64_t SplatRun::depositSpot(const SpotLine& L, float weight, SplatScratch& sc) const
{
    const double reach = mReach, h = mH;
    const Window& win = mWin;
    const std::size_t K = std::size_t(mK);
    // A spot within reach of where its line ends: part of it lies beyond the wall, where no window
    // sample can see it; sum its windows directly instead of from the tables.
    const bool nearWall = L.endFwd < reach + h || L.endBack > -(reach + h);
    const Xform* G = L.xforms.data();
    const openvdb::Vec3d t0(L.tangent);
    // First where every touched voxel's window lies (τ, d), then the deposits. A still's deposit
    // prefetches the table rows and the accumulators of the one kPrefetch ahead: its table (0.9 MB
    // for figure 12) fills most of a core's L2 beside the brick's arrays, and consecutive voxels'
    // rows lie apart. (Prefetching a comet table's rows measured no gain: a loop's deposit does
    // N frames' work.)
    sc.feet.clear();
    for (std::int64_t l : sc.touched) {
        const std::size_t li = std::size_t(l);
        if (double(sc.best[li]) >= (reach + 2.0) * (reach + 2.0)) continue;
        // The voxel's offset carried back along the line to the spot (linearised flow map): where
        // the voxel's own streamline passes the spot. Its part across the line is the distance
        // that decides the footprint, its part along the line shifts the window.
        const Xform& g = G[sc.foot[li]];
        const openvdb::Vec3f& o = sc.offset[li];
        const openvdb::Vec3d d0(g[0] * o[0] + g[3] * o[1] + g[6] * o[2], g[1] * o[0] + g[4] * o[1] + g[7] * o[2],
                                g[2] * o[0] + g[5] * o[1] + g[8] * o[2]);
        const double along = d0.dot(t0);
        const double d = std::sqrt(std::max(0.0, d0.lengthSqr() - along * along));
        const double tau = double(sc.arc[li]) + along;
        if (d >= reach || tau < mTauMin || tau > mTauMax) continue;
        sc.feet.push_back({li, tau, d});
    }
    constexpr std::size_t kPrefetch = 8;
    std::uint64_t deposits = 0;
    const std::size_t nFeet = sc.feet.size();
    for (std::size_t k = 0; k < nFeet; ++k) {
        if (!mComets && k + kPrefetch < nFeet) {
            const SplatScratch::Foot& next = sc.feet[k + kPrefetch];
            mTables.prefetch(next.tau, next.d);
            __builtin_prefetch(sc.acc.data() + next.li * K, 1);
        }
        const std::size_t li = sc.feet[k].li;
        const double tau = sc.feet[k].tau, d = sc.feet[k].d;
        if (mComets) {
            startBlock(li, sc);
            depositComets(L, weight, tau, d, sc, li);
            ++deposits;
            continue;
        }
        // x's window is cut where the spot's line ends at a wall: renormalise.
        int i0 = win.lo, i1 = win.hi;
        if (L.endBack > -1e299) i0 = std::max(i0, int(std::ceil((L.endBack - tau) / h - 1e-9)));
        if (L.endFwd < 1e299) i1 = std::min(i1, int(std::floor((L.endFwd - tau) / h + 1e-9)));
        if (i1 < i0) continue;
        double inside = mWinTotal;
        if (i0 != win.lo || i1 != win.hi) {
            inside = 0;
            for (int i = i0; i <= i1; ++i) inside += win.weight(i);
        }
        startBlock(li, sc);
        float* acc = sc.acc.data() + li * K;
        if (nearWall) {
            // The window's samples summed first, then added to the voxel (one rounding per spot).
            std::fill(sc.parts.begin(), sc.parts.end(), 0.0f);
            mTables.addDirect(tau, d, weight, i0, i1, inside, sc.parts.data());
            for (int p = 0; p < mTables.parts(); ++p) acc[p] += sc.parts[std::size_t(p)];
        } else {
            // One term per part: added in place (the same bits as through a zeroed buffer).
            mTables.add(tau, d, float(double(weight) * mWinTotal / inside), acc);
        }
        if (mSettings.ripple && float(d) < sc.nearest[li]) {
            // The window's own ripple normalisation (Σ e^{iθi} / N over the samples inside), from
            // the nearest spot line: 0 for a whole window.
            sc.nearest[li] = float(d);
            const std::array<double, 2> nz =
                (i0 != win.lo || i1 != win.hi) ? rippleNorm(win, mTheta, i0, i1) : mWholeNorm;
            acc[3 * mC] = float(nz[0]);
            acc[3 * mC + 1] = float(nz[1]);
        }
        ++deposits;
    }
    return deposits;
}

void SplatRun::handOver(const Brick& brick, SplatScratch& sc, const BrickSink& sink) const
{
    // The brick's blocks, channel-major per block; untouched blocks are flagged.
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    const std::size_t K = std::size_t(mK);
    sc.out.reserve(brick.blocks.size() * K * V);
    sc.blockTouched.assign(brick.blocks.size(), 0);
    bool any = false;
    for (std::size_t i = 0; i < brick.blocks.size(); ++i) {
        const std::size_t lb = sc.index.localBlock(mDomain.blockOrigin(brick.blocks[i]));
        if (!sc.dirty[lb]) continue;
        sc.blockTouched[i] = 1;
        any = true;
        float* dst = sc.out.data() + i * K * V;
        const float* src = sc.acc.data() + lb * V * K;
        detail::writeChannelMajor(
            K, V, [](std::size_t j) { return j; }, [&](std::size_t j, std::size_t k) { return src[j * K + k]; }, dst);
    }
    if (any) sink(BrickChannels{brick.id, &brick, mK, sc.out.data(), sc.blockTouched.data()});
}

} // namespace

LicStats splatSpotBricks(const ConvolveJob& job, const SpotInput& in, const BrickSink& sink)
{
    const LicSettings& settings = job.settings;
    settings.validate();
    if (in.radii.empty() || in.radii.size() > 4) {
        throw InputError("input.radii has " + std::to_string(in.radii.size()) +
                         " radii; between 1 and 4 width levels are supported");
    }
    const ThreadLimit limit(settings.threads);
    const auto start = std::chrono::steady_clock::now();
    std::vector<double> channelRadii(in.radii);
    for (double r : in.radii) channelRadii.push_back(r * in.haloScale);
    job.progress.begin("splat", job.domain.activeVoxelCount());
    SplatRun run(job.field, job.domain, job.layout, in.spots, channelRadii, settings);
    const std::uint64_t samples = run.traceLines();
    const std::vector<std::vector<std::uint32_t>> spotsOf = run.spotsPerBrick();
    std::vector<std::size_t> busy;
    for (std::size_t b = 0; b < job.layout.size(); ++b) {
        if (spotsOf[b].empty()) job.progress.advance(job.layout[b].activeVoxels); // nothing reaches it
        else busy.push_back(b);
    }
    LicStats stats = detail::forEachBrick<SplatScratch>(
        job.layout, busy, job.progress, true,
        [&](std::size_t b, const Brick& brick, SplatScratch& sc) { run.brick(brick, spotsOf[b], sc, sink); });
    job.progress.end();
    stats.voxels = job.domain.activeVoxelCount();
    stats.streamlines = in.spots.centers.size();
    stats.samples = samples;
    stats.bricks = busy.size();
    stats.brickDim = job.layout.dim();
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
}

int splatBrickDim(const LicSettings& settings)
{
    // No window tails at brick faces (a footprint crossing a face is rasterised by each brick it
    // reaches, from one trace), so bricks stay at 64³ for load balance. A comet loop's voxel
    // carries N·C accumulators (48 for the 24-frame vortex-ring loop): at 64³ a thread's
    // accumulators and hand-over would be 2 × 48 MiB, touched afresh for every brick; at 32³
    // they are 2 × 6 MiB and stay warm (24-frame ring loop: CPU −21 %, peak RSS 414 → 252 MiB;
    // the values are the same, the brick only moves which thread deposits where).
    return settings.comets > 1 ? 32 : 64;
}

double splatSpotReach(const LicSettings& settings, double maxSpotRadius)
{
    // The spot's own line runs n·h + R (+ a sample) each way, and deposits within √(R² + slab²)
    // of its coarse samples (SplatRun::nearestPoints).
    // A comet loop's line runs on by the comet spacing each way.
    const double R = maxSpotRadius + 0.5, slab = slabHalf(settings.step);
    const double train = settings.comets > 0 ? cometSpacing(settings, maxSpotRadius) : 0.0;
    return double(ghostMargin(settings)) + train + R + 1.0 + settings.step + std::sqrt(R * R + slab * slab) + 1.25;
}

double splatFieldReach(const LicSettings& settings, bool, double maxSpotRadius, int stride)
{
    // Every spot within splatSpotReach() is traced over its whole support (n·h + R each way)
    // from its centre, and the flow map carried along it needs derivatives: its whole line must
    // see the whole field's values, or its window would be cut elsewhere.
    const double integration = std::max({double(stride) * settings.step, 2.0, settings.step}) + 1.0;
    const double train = settings.comets > 0 ? cometSpacing(settings, maxSpotRadius) : 0.0;
    return splatSpotReach(settings, maxSpotRadius) + double(ghostMargin(settings)) + train + maxSpotRadius + 0.5 +
           settings.step + integration + 2.0;
}

} // namespace lic

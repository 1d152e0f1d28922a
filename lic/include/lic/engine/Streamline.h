// Streamlines in world space, parameterised by arc length: fixed-step RK4 and adaptive
// Dormand–Prince RK4(5) with error control, both emitting samples at uniform arc length.
#pragma once

#include "lic/field/Field.h"
#include "lic/util/Names.h"

#include <openvdb/math/Vec3.h>

#include <algorithm>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace lic {

enum class Integrator { RK4, RK45 };

/// Why a streamline ended.
enum class StopReason {
    Length,       ///< reached `maxSamples`
    Boundary,     ///< the next sample would leave the field's domain
    ZeroVelocity, ///< |v| fell below `minSpeed` (a critical point) or was not finite
    Caller        ///< the per-sample callback asked to stop
};

/// The integrators' names (a recipe's allowed values).
inline constexpr EnumName<Integrator> kIntegratorNames[] = {{Integrator::RK4, "rk4"}, {Integrator::RK45, "rk45"}};
inline std::span<const EnumName<Integrator>> integratorNames() { return kIntegratorNames; }
const char* toString(Integrator);
const char* toString(StopReason);
/// @throw lic::InputError for anything but "rk4" or "rk45".
Integrator integratorFromString(const std::string&);

/// How to trace. All lengths are WORLD units.
struct TraceSettings
{
    double step = 1.0;       ///< arc length between consecutive samples (> 0)
    int maxSamples = 100;    ///< samples per direction, not counting the seed
    Integrator integrator = Integrator::RK4;
    double tolerance = 1e-4; ///< RK45: largest accepted local error per step
    double maxStep = 4.0;    ///< RK45: largest integration step
    double minSpeed = 0.0;   ///< |v| ≤ minSpeed counts as zero velocity
};

namespace detail {

/// Unit flow direction times `sign` at a world position; false outside or at ~zero speed.
inline bool direction(const VelocityField& f, const openvdb::Vec3d& p, double sign, double minSpeed,
                      openvdb::Vec3d& d, StopReason& why)
{
    openvdb::Vec3d v;
    if (!f.sample(p, v)) {
        why = StopReason::Boundary;
        return false;
    }
    const double len = v.length();
    if (!(len > minSpeed) || !std::isfinite(len)) {
        why = StopReason::ZeroVelocity;
        return false;
    }
    d = v * (sign / len);
    return true;
}

/// One classical RK4 step of length h along the unit direction field.
inline bool rk4Step(const VelocityField& f, const openvdb::Vec3d& x, const openvdb::Vec3d& k1,
                    double h, double sign, double minSpeed, openvdb::Vec3d& out, StopReason& why)
{
    openvdb::Vec3d k2, k3, k4;
    if (!direction(f, x + k1 * (0.5 * h), sign, minSpeed, k2, why)) return false;
    if (!direction(f, x + k2 * (0.5 * h), sign, minSpeed, k3, why)) return false;
    if (!direction(f, x + k3 * h, sign, minSpeed, k4, why)) return false;
    out = x + (k1 + 2.0 * (k2 + k3) + k4) * (h / 6.0);
    return f.contains(out) || ((why = StopReason::Boundary), false);
}

StopReason traceRK45(const VelocityField& f, const openvdb::Vec3d& seed, double sign,
                     const TraceSettings& s, std::vector<openvdb::Vec3d>& out,
                     bool (*onSample)(void*, const openvdb::Vec3d&), void* ctx);

} // namespace detail

/// Trace the streamline through `seed` downstream (`sign` = +1) or upstream (−1), appending to
/// `out` the points at arc length h, 2h, … (h = `s.step`) until `s.maxSamples` points, the
/// domain boundary or zero velocity. The seed itself is not appended. After each appended point
/// `onSample(point)` is called; returning false stops the trace with StopReason::Caller.
template<typename OnSample>
StopReason traceStreamline(const VelocityField& f, const openvdb::Vec3d& seed, double sign,
                           const TraceSettings& s, std::vector<openvdb::Vec3d>& out,
                           OnSample&& onSample)
{
    if (s.integrator == Integrator::RK45) {
        auto thunk = [](void* c, const openvdb::Vec3d& p) -> bool {
            return (*static_cast<std::remove_reference_t<OnSample>*>(c))(p);
        };
        return detail::traceRK45(f, seed, sign, s, out, thunk, &onSample);
    }
    StopReason why = StopReason::Length;
    openvdb::Vec3d x = seed, k1;
    if (!detail::direction(f, x, sign, s.minSpeed, k1, why)) return why;
    for (int i = 0; i < s.maxSamples; ++i) {
        openvdb::Vec3d next;
        if (!detail::rk4Step(f, x, k1, s.step, sign, s.minSpeed, next, why)) return why;
        out.push_back(next);
        if (!onSample(next)) return StopReason::Caller;
        x = next;
        if (i + 1 < s.maxSamples && !detail::direction(f, x, sign, s.minSpeed, k1, why)) return why;
    }
    return StopReason::Length;
}

namespace detail {
// Vec3d arithmetic of the index-space tracer, always inlined. In the long lockstep loop below GCC
// stops inlining OpenVDB's Vec3 operator+ (and calls it a dozen times per step pair); these
// compute exactly what the operator expressions they replace compute, in the same order.
/// x + k · s
[[gnu::always_inline]] inline openvdb::Vec3d stepAlong(const openvdb::Vec3d& x, const openvdb::Vec3d& k, double s)
{
    return openvdb::Vec3d(x[0] + k[0] * s, x[1] + k[1] * s, x[2] + k[2] * s);
}
/// x + (k1 + 2 (k2 + k3) + k4) · s: the RK4 update
[[gnu::always_inline]] inline openvdb::Vec3d rk4Update(const openvdb::Vec3d& x, const openvdb::Vec3d& k1, const openvdb::Vec3d& k2,
                                                      const openvdb::Vec3d& k3, const openvdb::Vec3d& k4, double s)
{
    openvdb::Vec3d r;
    for (int a = 0; a < 3; ++a) r[a] = x[a] + (k1[a] + 2.0 * (k2[a] + k3[a]) + k4[a]) * s;
    return r;
}

/// One RK4 step of world arc length h in the field's INDEX space (directions from
/// VelocityField::directionIndex): the world-space step mapped through the affine transform.
inline bool rk4StepIndex(const VelocityField& f, const openvdb::Vec3d& x, const openvdb::Vec3d& k1, double h,
                         double sign, double minSpeed, openvdb::Vec3d& out)
{
    openvdb::Vec3d k2, k3, k4;
    if (!f.directionIndex(stepAlong(x, k1, 0.5 * h), sign, minSpeed, k2)) return false;
    if (!f.directionIndex(stepAlong(x, k2, 0.5 * h), sign, minSpeed, k3)) return false;
    if (!f.directionIndex(stepAlong(x, k3, h), sign, minSpeed, k4)) return false;
    out = rk4Update(x, k1, k2, k3, k4, h / 6.0);
    return f.containsIndex(out);
}

/// One side of a line being traced in index space (see traceIndexPair).
struct IndexSide
{
    openvdb::Vec3d x, k1;    ///< position and direction there
    double sign = 1.0;
    int done = 0;            ///< samples emitted
    bool alive = true;
    bool single = false;     ///< single steps from here on (near a wall or critical point)
    StopReason why = StopReason::Length;
};

/// The cubic Hermite basis {h00, h10, h01, h11} at t = j/m (the interpolation between a long
/// step's end points).
constexpr void hermiteBasis(int j, int m, double* h)
{
    const double t = double(j) / double(m), t2 = t * t, t3 = t2 * t;
    h[0] = 2 * t3 - 3 * t2 + 1;
    h[1] = t3 - 2 * t2 + t;
    h[2] = 3 * t2 - 2 * t3;
    h[3] = t3 - t2;
}

/// hermiteBasis for 1 ≤ j < m ≤ kMaxStride (the automatic strides), evaluated once at compile
/// time: IEEE double, round to nearest, so the same bits as at run time.
struct HermiteTable
{
    static constexpr int kMaxStride = 8;
    double h[kMaxStride + 1][kMaxStride][4] = {};
    constexpr HermiteTable()
    {
        for (int m = 2; m <= kMaxStride; ++m)
            for (int j = 1; j < m; ++j) hermiteBasis(j, m, h[m][j]);
    }
};
inline constexpr HermiteTable kHermite{};

/// Emit the samples of an accepted long step x → x1 (Hermite between the end points, x1 last).
template<typename OnSample>
bool emitLongStep(IndexSide& s, int m, double H, const openvdb::Vec3d& x1, const openvdb::Vec3d& d1, OnSample& on)
{
    const openvdb::Vec3d t0 = s.k1 * H, t1 = d1 * H;
    for (int j = 1; j < m; ++j) {
        double hc[4];
        const double* hj = hc;
        if (m <= HermiteTable::kMaxStride) hj = kHermite.h[m][j];
        else hermiteBasis(j, m, hc);
        const double h00 = hj[0], h10 = hj[1], h01 = hj[2], h11 = hj[3];
        openvdb::Vec3d p; // h00 x + h10 t0 + h01 x1 + h11 t1, summed left to right
        for (int a = 0; a < 3; ++a) p[a] = h00 * s.x[a] + h10 * t0[a] + h01 * x1[a] + h11 * t1[a];
        if (!on(p)) return false;
    }
    if (!on(x1)) return false;
    s.x = x1;
    s.k1 = d1;
    s.done += m;
    return true;
}

/// Advance one side by one long step (or, in single mode, one step of h).
template<typename OnSample>
void advanceSide(const VelocityField& f, IndexSide& s, const TraceSettings& ts, int stride, OnSample& on)
{
    if (s.done >= ts.maxSamples) {
        s.alive = false;
        s.why = StopReason::Length;
        return;
    }
    const int m = std::min(stride, ts.maxSamples - s.done);
    if (!s.single && m > 1) {
        const double H = ts.step * double(m);
        openvdb::Vec3d x1, d1;
        if (rk4StepIndex(f, s.x, s.k1, H, s.sign, ts.minSpeed, x1) && f.directionIndex(x1, s.sign, ts.minSpeed, d1)) {
            if (!emitLongStep(s, m, H, x1, d1, on)) {
                s.alive = false;
                s.why = StopReason::Caller;
            }
            return;
        }
        s.single = true;
    }
    openvdb::Vec3d next;
    if (!rk4StepIndex(f, s.x, s.k1, ts.step, s.sign, ts.minSpeed, next)) {
        s.alive = false;
        s.why = StopReason::Boundary;
        return;
    }
    if (!on(next)) {
        s.alive = false;
        s.why = StopReason::Caller;
        return;
    }
    s.x = next;
    ++s.done;
    if (s.done < ts.maxSamples && !f.directionIndex(s.x, s.sign, ts.minSpeed, s.k1)) {
        s.alive = false;
        s.why = StopReason::Boundary;
    }
}

/// True when side `s` has a step to take (alive, below maxSamples): what stepLanes() advances.
inline bool takesStep(const IndexSide& s, const TraceSettings& ts) { return s.alive && s.done < ts.maxSamples; }

/// Advance N sides, each takesStep(), by one step each, with their RK4 stages interleaved so the
/// CPU overlaps the N latency chains (sides of one line or of several; see stepSides()). Each
/// side's step and arithmetic are advanceSide()'s: a long step of `stride` samples, or a single
/// step of h in single mode or with one sample of room left; so the same positions and ends. A
/// side whose long step fails turns single (its next step is single), one its callback stops
/// ends (Caller), one that reaches maxSamples ends (Length), a single step that leaves the domain
/// or meets zero speed ends the side (Boundary).
template<int N, typename OnSample>
void stepLanes(const VelocityField& f, IndexSide* const* S, OnSample* const* on, const TraceSettings& ts, int stride)
{
    using openvdb::Vec3d;
    Vec3d k2[N], k3[N], k4[N], k1n[N], x1[N];
    bool ok[N], dirOk[N], single[N];
    double H[N];
    int m[N];
    for (int i = 0; i < N; ++i) {
        m[i] = std::min(stride, ts.maxSamples - S[i]->done);
        single[i] = S[i]->single || m[i] <= 1;
        if (single[i]) m[i] = 1;
        H[i] = single[i] ? ts.step : ts.step * double(m[i]);
    }
    for (int i = 0; i < N; ++i)
        ok[i] = f.directionIndex(stepAlong(S[i]->x, S[i]->k1, 0.5 * H[i]), S[i]->sign, ts.minSpeed, k2[i]);
    for (int i = 0; i < N; ++i)
        ok[i] = ok[i] && f.directionIndex(stepAlong(S[i]->x, k2[i], 0.5 * H[i]), S[i]->sign, ts.minSpeed, k3[i]);
    for (int i = 0; i < N; ++i)
        ok[i] = ok[i] && f.directionIndex(stepAlong(S[i]->x, k3[i], H[i]), S[i]->sign, ts.minSpeed, k4[i]);
    for (int i = 0; i < N; ++i)
        if (ok[i]) x1[i] = rk4Update(S[i]->x, S[i]->k1, k2[i], k3[i], k4[i], H[i] / 6.0);
    for (int i = 0; i < N; ++i) {
        ok[i] = ok[i] && f.containsIndex(x1[i]);
        // A single step's last sample needs no direction (advanceSide does not take it).
        dirOk[i] = ok[i] && (single[i] && S[i]->done + 1 >= ts.maxSamples
                                 ? true
                                 : f.directionIndex(x1[i], S[i]->sign, ts.minSpeed, k1n[i]));
    }
    for (int i = 0; i < N; ++i) {
        IndexSide& s = *S[i];
        if (!single[i]) {
            if (!dirOk[i]) {
                s.single = true;
            } else if (!emitLongStep(s, m[i], H[i], x1[i], k1n[i], *on[i])) {
                s.alive = false;
                s.why = StopReason::Caller;
            } else if (s.done >= ts.maxSamples) {
                s.alive = false;
                s.why = StopReason::Length;
            }
            continue;
        }
        if (!ok[i]) {
            s.alive = false;
            s.why = StopReason::Boundary;
        } else if (!(*on[i])(x1[i])) {
            s.alive = false;
            s.why = StopReason::Caller;
        } else {
            s.x = x1[i];
            ++s.done;
            if (s.done >= ts.maxSamples) {
                s.alive = false;
                s.why = StopReason::Length;
            } else if (!dirOk[i]) {
                s.alive = false;
                s.why = StopReason::Boundary;
            } else {
                s.k1 = k1n[i];
            }
        }
    }
}

/// A side starting at `seedIdx` in direction `sign` (dead, Boundary, where the seed has no
/// direction).
inline IndexSide startSide(const VelocityField& f, const openvdb::Vec3d& seedIdx, double sign, double minSpeed)
{
    IndexSide t;
    t.sign = sign;
    t.x = seedIdx;
    if (!f.directionIndex(seedIdx, sign, minSpeed, t.k1)) {
        t.alive = false;
        t.why = StopReason::Boundary;
    }
    return t;
}

/// One step of each live side among `n` (callbacks `on[i]`): the ones with a step to take in
/// lanes of three (stepLanes), the rest by advanceSide(), which ends them (Length).
template<typename OnSample>
void stepSides(const VelocityField& f, IndexSide* const* sides, OnSample* const* on, int n, const TraceSettings& ts,
               int stride)
{
    constexpr int kMax = 8;
    IndexSide* lanes[kMax];
    OnSample* laneOn[kMax];
    int k = 0;
    for (int i = 0; i < n; ++i) {
        if (!sides[i]->alive) continue;
        if (takesStep(*sides[i], ts)) {
            lanes[k] = sides[i];
            laneOn[k++] = on[i];
        } else {
            advanceSide(f, *sides[i], ts, stride, *on[i]);
        }
    }
    for (int i = 0; i < k; i += 3) {
        switch (std::min(3, k - i)) {
        case 3: stepLanes<3>(f, lanes + i, laneOn + i, ts, stride); break;
        case 2: stepLanes<2>(f, lanes + i, laneOn + i, ts, stride); break;
        default: advanceSide(f, *lanes[i], ts, stride, *laneOn[i]); break;
        }
    }
}
} // namespace detail

/// The fast engine's tracer: both sides of the streamline through `seedIdx` (upstream to `onBack`,
/// downstream to `onFwd`), as two traceStreamline() calls would give them, but in the field's
/// INDEX space (VelocityField::directionIndex; no transform per lookup) and in lockstep:
/// the two sides' RK4 stages are interleaved, so the CPU overlaps their latency chains. RK4
/// integrates `stride` samples per step and places the ones between by cubic Hermite
/// interpolation; where a long step fails, that side continues in single steps of h, so it ends
/// where a single-step trace would. Positions passed to the callbacks (`bool(const Vec3d&)`;
/// false stops that side) are field index positions; the settings' lengths stay world units.
/// RK45 traces each side in world space (traceStreamline) and maps each sample. Returns why each
/// side ended {upstream, downstream}; RK4 reports walls and critical points both as Boundary.
template<typename OnBack, typename OnFwd>
std::pair<StopReason, StopReason> traceIndexPair(const VelocityField& f, const openvdb::Vec3d& seedIdx,
                                                 const TraceSettings& s, int stride,
                                                 std::vector<openvdb::Vec3d>& scratch, OnBack&& onBack,
                                                 OnFwd&& onFwd)
{
    using openvdb::Vec3d;
    if (s.integrator == Integrator::RK45) {
        const Vec3d w = f.map().toWorld(seedIdx);
        scratch.clear();
        const StopReason a = traceStreamline(f, w, -1.0, s, scratch, [&](const Vec3d& p) { return onBack(f.map().toIndex(p)); });
        scratch.clear();
        const StopReason b = traceStreamline(f, w, +1.0, s, scratch, [&](const Vec3d& p) { return onFwd(f.map().toIndex(p)); });
        return {a, b};
    }
    // Both sides stepped together (their RK4 stages interleaved), each with its own callback.
    struct Sink
    {
        std::remove_reference_t<OnBack>* back;
        std::remove_reference_t<OnFwd>* fwd;
        bool upstream;
        bool operator()(const Vec3d& p) const { return upstream ? (*back)(p) : (*fwd)(p); }
    };
    detail::IndexSide A = detail::startSide(f, seedIdx, -1.0, s.minSpeed);
    detail::IndexSide B = detail::startSide(f, seedIdx, +1.0, s.minSpeed);
    Sink sinkA{&onBack, &onFwd, true}, sinkB{&onBack, &onFwd, false};
    detail::IndexSide* const sides[2] = {&A, &B};
    Sink* const sinks[2] = {&sinkA, &sinkB};
    stride = std::max(1, stride);
    while (A.alive || B.alive) detail::stepSides(f, sides, sinks, 2, s, stride);
    return {A.why, B.why};
}

/// Convenience overload without a callback.
inline StopReason traceStreamline(const VelocityField& f, const openvdb::Vec3d& seed, double sign,
                                  const TraceSettings& s, std::vector<openvdb::Vec3d>& out)
{
    return traceStreamline(f, seed, sign, s, out, [](const openvdb::Vec3d&) { return true; });
}

} // namespace lic

// Streamlines in world space, parameterised by arc length: fixed-step RK4 and adaptive
// Dormand–Prince RK4(5) with error control, both emitting samples at uniform arc length.
#pragma once

#include "lic/Field.h"

#include <openvdb/math/Vec3.h>

#include <string>
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

/// Convenience overload without a callback.
inline StopReason traceStreamline(const VelocityField& f, const openvdb::Vec3d& seed, double sign,
                                  const TraceSettings& s, std::vector<openvdb::Vec3d>& out)
{
    return traceStreamline(f, seed, sign, s, out, [](const openvdb::Vec3d&) { return true; });
}

} // namespace lic

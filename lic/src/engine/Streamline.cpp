#include "lic/engine/Streamline.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"

#include <algorithm>
#include <cmath>

namespace lic {

const char* toString(Integrator i) { return nameOf<Integrator>(kIntegratorNames, i); }

const char* toString(StopReason r)
{
    switch (r) {
    case StopReason::Length: return "length";
    case StopReason::Boundary: return "boundary";
    case StopReason::ZeroVelocity: return "zero-velocity";
    case StopReason::Caller: return "caller";
    }
    return "?";
}

Integrator integratorFromString(const std::string& s)
{
    return valueOf<Integrator>(kIntegratorNames, s, "integrator");
}

namespace detail {

namespace {
// Dormand–Prince 5(4) tableau (Hairer, Nørsett & Wanner, Table 5.2).
constexpr double a21 = 1.0 / 5;
constexpr double a31 = 3.0 / 40, a32 = 9.0 / 40;
constexpr double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
constexpr double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                 a54 = -212.0 / 729;
constexpr double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176,
                 a65 = -5103.0 / 18656;
constexpr double b1 = 35.0 / 384, b3 = 500.0 / 1113, b4 = 125.0 / 192, b5 = -2187.0 / 6784,
                 b6 = 11.0 / 84;
// Error weights: 5th-order minus embedded 4th-order solution.
constexpr double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200,
                 e6 = 22.0 / 525, e7 = -1.0 / 40;
} // namespace

StopReason traceRK45(const VelocityField& f, const openvdb::Vec3d& seed, double sign,
                     const TraceSettings& s, std::vector<openvdb::Vec3d>& out,
                     bool (*onSample)(void*, const openvdb::Vec3d&), void* ctx)
{
    using openvdb::Vec3d;
    StopReason why = StopReason::Length;
    Vec3d x = seed, k1;
    if (!direction(f, x, sign, s.minSpeed, k1, why)) return why;

    const double hMin = s.step * 1e-3;
    double H = std::min(s.step, s.maxStep);
    double arc = 0.0; // arc length at x
    int count = 0;
    while (count < s.maxSamples) {
        Vec3d k2, k3, k4, k5, k6, k7;
        const bool ok =
            direction(f, x + H * (a21 * k1), sign, s.minSpeed, k2, why) &&
            direction(f, x + H * (a31 * k1 + a32 * k2), sign, s.minSpeed, k3, why) &&
            direction(f, x + H * (a41 * k1 + a42 * k2 + a43 * k3), sign, s.minSpeed, k4, why) &&
            direction(f, x + H * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4), sign, s.minSpeed, k5,
                      why) &&
            direction(f, x + H * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5), sign,
                      s.minSpeed, k6, why);
        Vec3d x1;
        bool ok7 = false;
        if (ok) {
            x1 = x + H * (b1 * k1 + b3 * k3 + b4 * k4 + b5 * k5 + b6 * k6);
            ok7 = direction(f, x1, sign, s.minSpeed, k7, why); // FSAL: k7 = f(x1)
        }
        if (!ok || !ok7) {
            // Near the boundary or a critical point: shorten the step until it fits.
            if (H <= hMin) return why;
            H = std::max(hMin, 0.5 * H);
            continue;
        }
        const double err =
            (H * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7)).length();
        if (err > s.tolerance && H > hMin) {
            H = std::max(hMin, H * std::max(0.2, 0.9 * std::pow(s.tolerance / err, 0.2)));
            continue;
        }
        // Accepted: emit the uniform arc-length samples inside (arc, arc + H] by cubic Hermite
        // interpolation between the step's end points and their (unit) derivatives.
        for (;;) {
            const double target = double(count + 1) * s.step;
            if (target > arc + H * (1 + 1e-12) || count >= s.maxSamples) break;
            const double t = std::min(1.0, (target - arc) / H), t2 = t * t, t3 = t2 * t;
            const Vec3d p = (2 * t3 - 3 * t2 + 1) * x + (t3 - 2 * t2 + t) * H * k1 +
                            (-2 * t3 + 3 * t2) * x1 + (t3 - t2) * H * k7;
            out.push_back(p);
            ++count;
            if (!onSample(ctx, p)) return StopReason::Caller;
        }
        arc += H;
        x = x1;
        k1 = k7;
        const double grow = err > 0 ? 0.9 * std::pow(s.tolerance / err, 0.2) : 5.0;
        H = std::min(s.maxStep, H * std::clamp(grow, 0.2, 5.0));
    }
    return StopReason::Length;
}

} // namespace detail
} // namespace lic

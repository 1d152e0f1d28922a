#include "lic/engine/Engine.h"

#include "lic/util/Error.h"

#include <cmath>
#include <algorithm>
#include <sstream>

namespace lic {

const char* toString(EngineType e)
{
    switch (e) {
    case EngineType::Naive: return "naive";
    case EngineType::Fast: return "fast";
    case EngineType::Splat: return "splat";
    }
    return "?";
}

EngineType engineFromString(const std::string& s)
{
    if (s == "naive") return EngineType::Naive;
    if (s == "fast") return EngineType::Fast;
    if (s == "splat") return EngineType::Splat;
    throw InputError("engine \"" + s + "\" is unknown; expected naive, fast or splat");
}

const char* toString(KernelType k) { return k == KernelType::Exp ? "exp" : "box"; }

KernelType kernelFromString(const std::string& s)
{
    if (s == "box") return KernelType::Box;
    if (s == "exp") return KernelType::Exp;
    throw InputError("kernel \"" + s + "\" is unknown; expected box or exp");
}

int LicSettings::halfSamples() const
{
    return std::max(1, int(std::lround(length / step)));
}

void LicSettings::validate() const
{
    auto fail = [](const std::string& what, double got, const std::string& expected) {
        std::ostringstream msg;
        msg << what << " " << got << " is out of range; expected " << expected;
        throw InputError(msg.str());
    };
    if (!(length > 0) || !std::isfinite(length)) fail("length", length, "> 0 output voxels");
    if (!(step > 0) || !std::isfinite(step)) fail("step", step, "> 0 output voxels");
    if (step > length) fail("step", step, "<= length (" + std::to_string(length) + ")");
    if (length / step > 1e6) fail("length/step", length / step, "at most 1e6 samples per direction");
    if (!(tolerance > 0)) fail("tolerance", tolerance, "> 0");
    if (kernel == KernelType::Exp && !(decay > 0 && decay < 1)) fail("decay", decay, "in (0, 1)");
    if (minHits < 1 || minHits > 64) fail("min_hits", minHits, "1..64");
    if (threads < 0) fail("threads", threads, ">= 0 (0 = all cores)");
    if (coveredRun < 1) fail("covered run", coveredRun, ">= 1");
    if (maxStreamline < 0) fail("max streamline", maxStreamline, ">= 0");
    if (brick != 0 && (brick < 8 || brick > 512 || brick % 8 != 0))
        fail("brick", brick, "a multiple of 8 in 8..512 output voxels (0 = automatic)");
    if (stride < 0 || stride > 64) fail("stride", stride, "0..64 samples per integration step (0 = automatic)");
}

namespace detail {

TraceSettings traceSettings(const VelocityField& field, const OutputDomain& domain,
                            const LicSettings& settings)
{
    const double vs = domain.voxelSize();
    TraceSettings ts;
    ts.step = settings.step * vs;
    ts.maxSamples = settings.halfSamples();
    ts.integrator = settings.integrator;
    ts.tolerance = settings.tolerance * vs;
    ts.maxStep = std::max(ts.step, 2.0 * vs);
    ts.minSpeed = field.maxSpeed() * 1e-6;
    return ts;
}

void windowSums(KernelType kernel, double decay, int n, std::size_t N, int W, const double* vals,
                double* win, double* norm, std::vector<double>& scratch)
{
    const std::size_t nn = std::size_t(n);
    if (kernel == KernelType::Box) {
        scratch.assign((N + 1) * std::size_t(W), 0.0); // prefix sums
        for (std::size_t i = 0; i < N; ++i)
            for (int c = 0; c < W; ++c) scratch[(i + 1) * W + c] = scratch[i * W + c] + vals[i * W + c];
        for (std::size_t i = 0; i < N; ++i) {
            const std::size_t a = i >= nn ? i - nn : 0, b = std::min(N - 1, i + nn);
            for (int c = 0; c < W; ++c) win[i * W + c] = scratch[(b + 1) * W + c] - scratch[a * W + c];
            norm[i] = double(b - a + 1);
        }
        return;
    }
    scratch.assign((N + 1) * std::size_t(W), 0.0); // E_i, with E_N = 0
    for (std::size_t i = N; i-- > 0;)
        for (int c = 0; c < W; ++c) scratch[i * W + c] = vals[i * W + c] + decay * scratch[(i + 1) * W + c];
    const double cn1 = std::pow(decay, double(n + 1));
    for (std::size_t i = 0; i < N; ++i) {
        const std::size_t end = i + nn + 1; // first sample past the window
        for (int c = 0; c < W; ++c)
            win[i * W + c] = scratch[i * W + c] - (end < N ? cn1 * scratch[end * W + c] : 0.0);
        const double K = double(std::min(nn, N - 1 - i)); // window is samples i … i+K
        norm[i] = (1.0 - std::pow(decay, K + 1.0)) / (1.0 - decay);
    }
}

int ripplePeriod(const LicSettings& settings)
{
    // One ripple per window, either kernel: the 2n+1 samples of a box window, the n+1 of an exp one.
    const int n = settings.halfSamples();
    return settings.kernel == KernelType::Box ? 2 * n + 1 : n + 1;
}

int integrationStride(const OutputDomain& domain, const LicSettings& settings)
{
    if (settings.stride > 0) return settings.stride;
    // About one field voxel per RK4 step (the trilinear field has no detail finer than that).
    return std::clamp(int(std::floor(double(domain.upsample()) / settings.step + 1e-9)), 1, 8);
}

} // namespace detail
} // namespace lic

#include "lic/engine/Kernels.h"

#include "lic/texture/Noise.h"
#include "lic/texture/Spots.h"

#include <algorithm>
#include <cmath>

namespace lic {

double spotPeak(const LicSettings& settings, double radius)
{
    const int n = settings.halfSamples();
    const double h = settings.step;
    const int reach = int(std::ceil((radius + 1.0) / h)) + 1;
    const int M = 2 * n + reach + 2;
    const std::size_t N = std::size_t(2 * M + 1);
    std::vector<double> vals(N), win(N), norm(N), scratch;
    double peak = 0.0;
    for (double phase : {0.0, 0.25, 0.5, 0.75}) {
        for (std::size_t j = 0; j < N; ++j) {
            double slope;
            vals[j] = spotProfile(std::abs((double(j) - M + phase) * h), radius, slope);
        }
        detail::windowSums(settings.kernel, settings.decay, n, N, 1, vals.data(), win.data(), norm.data(), scratch);
        // Interior windows only (complete on both sides).
        for (std::size_t i = std::size_t(n); i + std::size_t(n) < N; ++i) peak = std::max(peak, win[i] / norm[i]);
    }
    return peak;
}

double cometSpacing(const LicSettings& settings, double maxRadius)
{
    const int n = settings.halfSamples();
    const double extent = double(settings.kernel == KernelType::Box ? 2 * n : n) * settings.step;
    return extent + 4.0 * (maxRadius + 0.5);
}

double cometFade(double a, double spacing)
{
    if (!(std::abs(a) < spacing)) return 0.0;
    const double c = std::cos(3.14159265358979323846 * a / (2.0 * spacing));
    return c * c;
}

int cometPhase(const openvdb::Vec3d& centre, int frames)
{
    // The noise's coordinate hash over the centre to 1/256 voxel (distinct spots are ≥ 0.88·d apart).
    constexpr std::uint64_t kCometSeed = 0x636f6d6574ull; // "comet"
    auto q = [&](int a) { return int(std::lround(centre[a] * 256.0)); };
    return int(hashCoord(kCometSeed, q(0), q(1), q(2)) % std::uint64_t(frames));
}

namespace detail {

namespace {
// WC > 0: W known at compile time (the fast engine's noise lines, W = 4), so the per-sample loops
// over the channels unroll into vector code; WC = 0: W at run time. The same operations, in the same
// order, either way.
template<int WC>
void windowSumsW(KernelType kernel, double decay, int n, std::size_t N, int Wrt, const double* vals, double* win,
                 double* norm, std::vector<double>& scratch)
{
    const std::size_t W = WC > 0 ? std::size_t(WC) : std::size_t(Wrt);
    const std::size_t nn = std::size_t(n);
    // N + 1 rows of W, of which only the one read before it is written is cleared (a comet loop's
    // W = N·4C made clearing them all 6 % of its time); the scratch only grows.
    if (scratch.size() < (N + 1) * W) scratch.resize((N + 1) * W);
    double* S = scratch.data();
    if (kernel == KernelType::Box) {
        std::fill_n(S, W, 0.0); // prefix sums, P_0 = 0
        for (std::size_t i = 0; i < N; ++i)
            for (std::size_t c = 0; c < W; ++c) S[(i + 1) * W + c] = S[i * W + c] + vals[i * W + c];
        for (std::size_t i = 0; i < N; ++i) {
            const std::size_t a = i >= nn ? i - nn : 0, b = std::min(N - 1, i + nn);
            for (std::size_t c = 0; c < W; ++c) win[i * W + c] = S[(b + 1) * W + c] - S[a * W + c];
            norm[i] = double(b - a + 1);
        }
        return;
    }
    std::fill_n(S + N * W, W, 0.0); // E_i, with E_N = 0
    for (std::size_t i = N; i-- > 0;)
        for (std::size_t c = 0; c < W; ++c) S[i * W + c] = vals[i * W + c] + decay * S[(i + 1) * W + c];
    const double cn1 = std::pow(decay, double(n + 1));
    for (std::size_t i = 0; i < N; ++i) {
        const std::size_t end = i + nn + 1; // first sample past the window
        for (std::size_t c = 0; c < W; ++c)
            win[i * W + c] = S[i * W + c] - (end < N ? cn1 * S[end * W + c] : 0.0);
        const double K = double(std::min(nn, N - 1 - i)); // window is samples i … i+K
        norm[i] = (1.0 - std::pow(decay, K + 1.0)) / (1.0 - decay);
    }
}
} // namespace

void windowSums(KernelType kernel, double decay, int n, std::size_t N, int W, const double* vals, double* win,
                double* norm, std::vector<double>& scratch)
{
    if (W == 4) windowSumsW<4>(kernel, decay, n, N, W, vals, win, norm, scratch);
    else windowSumsW<0>(kernel, decay, n, N, W, vals, win, norm, scratch);
}

int ripplePeriod(const LicSettings& settings)
{
    // One ripple per window, either kernel: the 2n+1 samples of a box window, the n+1 of an exp one.
    const int n = settings.halfSamples();
    return settings.kernel == KernelType::Box ? 2 * n + 1 : n + 1;
}

} // namespace detail
} // namespace lic

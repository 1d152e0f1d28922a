// Seamless cyclic animation of steady flow from one trace: the periodic ripple kernel.
#pragma once

#include "lic/engine/Engine.h"

#include <cmath>
#include <vector>

namespace lic {

/// Ripple depth α of the frame kernel w_f(k) = 1 + α·cos(θk + 2π(f−1)/N), k the signed sample
/// offset (downstream positive), θ = 2π/(2n+1) (one ripple per box window).
/// α < 1 keeps every weight positive, so truncated windows never divide by ~0.
constexpr double kRippleDepth = 0.8;

/// Frame f (1-based) of N for texture channel c, per slot, from a ripple LicResult (3·C + 2
/// channels: A, Re Z, Im Z per channel, then Re N, Im N; all divided by the sample count):
///   I_f = (A + α·Re(e^{−iφ_f} Z)) / (1 + α·Re(e^{−iφ_f} N)),  φ_f = −2π(f−1)/N,
/// i.e. weights 1 + α·cos(θk + 2π(f−1)/N): the weight's crest moves upstream (to smaller k) as f
/// grows, so each voxel sees texture from further upstream and the pattern moves DOWNSTREAM,
/// (2n+1)·step/N output voxels per frame (tested on `uniform`). Frame N+1 equals frame 1.
/// The phase of frame f (1-based) of N as (cos φ_f, sin φ_f), φ_f = −2π(f−1)/N.
struct FramePhase
{
    double c = 1.0, s = 0.0;
    FramePhase() = default;
    FramePhase(int f, int frames)
    {
        const double phi = -2.0 * 3.14159265358979323846 * double(f - 1) / double(frames);
        c = std::cos(phi);
        s = std::sin(phi);
    }
};

/// One voxel of composeFrame(): the frame value from A, Re Z, Im Z of its channel and Re N, Im N.
inline float rippleFrameValue(double A, double Zr, double Zi, double Nr, double Ni, const FramePhase& ph)
{
    // Re(e^{−iφ}(x + iy)) = x cos φ + y sin φ
    const double num = A + kRippleDepth * (Zr * ph.c + Zi * ph.s);
    const double den = 1.0 + kRippleDepth * (Nr * ph.c + Ni * ph.s);
    return den > 0 ? float(num / den) : 0.0f;
}

inline std::vector<float> composeFrame(const LicResult& r, int channels, int c, int f, int frames)
{
    const FramePhase ph(f, frames);
    const auto& A = r.channels[std::size_t(c)];
    const auto& Zr = r.channels[std::size_t(channels + c)];
    const auto& Zi = r.channels[std::size_t(2 * channels + c)];
    const auto& Nr = r.channels[std::size_t(3 * channels)];
    const auto& Ni = r.channels[std::size_t(3 * channels + 1)];
    std::vector<float> out(A.size(), 0.0f);
    for (std::size_t s = 0; s < A.size(); ++s) out[s] = rippleFrameValue(A[s], Zr[s], Zi[s], Nr[s], Ni[s], ph);
    return out;
}

} // namespace lic

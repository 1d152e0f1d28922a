// Line integral convolution engines: settings, results and the entry point.
#pragma once

#include "lic/Field.h"
#include "lic/OutputDomain.h"
#include "lic/Progress.h"
#include "lic/Streamline.h"

#include <cstdint>
#include <string>
#include <vector>

namespace lic {

enum class EngineType {
    Naive, ///< every voxel gathers along its own streamline (the reference)
    Fast   ///< Stalling–Hege fast-LIC: long streamlines deposit into every voxel they cross
};
const char* toString(EngineType);
/// @throw lic::InputError for names other than "naive" and "fast".
EngineType engineFromString(const std::string&);

enum class KernelType {
    Box, ///< uniform weights over n samples each way
    Exp  ///< oriented: weights c^k over the n samples downstream (seed §7); bright heads point downstream
};
const char* toString(KernelType);
/// @throw lic::InputError for names other than "box" and "exp".
KernelType kernelFromString(const std::string&);

/// What to convolve and how. Lengths are in OUTPUT VOXELS (the smallest edge of an output voxel).
struct LicSettings
{
    EngineType engine = EngineType::Fast;
    Integrator integrator = Integrator::RK4;
    KernelType kernel = KernelType::Box;
    double decay = 0.9;      ///< exp kernel: weight ratio c of consecutive samples, in (0, 1)
    /// Also produce the ripple sums a cyclic animation is composed from (box kernel only; see
    /// Animation.h). The result then has 3·C + 2 channels.
    bool ripple = false;
    double length = 20.0;    ///< kernel half-length, one direction (> 0)
    double step = 0.5;       ///< arc length between samples (> 0, ≤ length)
    double tolerance = 1e-3; ///< RK45 local error per step
    int minHits = 2;         ///< fast: a voxel with fewer deposits seeds its own streamline
    int threads = 0;         ///< worker threads, 0 = all cores
    /// fast: a streamline stops after this many consecutive samples in voxels that were
    /// already covered (plus the kernel half-length it needs to finish its window).
    int coveredRun = 64;
    /// fast: longest streamline per direction in output voxels; 0 = automatic (see FastLic.h).
    double maxStreamline = 0.0;

    /// Samples per direction of the kernel: round(length / step), at least 1.
    int halfSamples() const;
    /// @throw lic::InputError naming the first out-of-range parameter.
    void validate() const;
};

/// Counters of one convolution, identical for any thread count.
struct LicStats
{
    std::uint64_t voxels = 0;      ///< active output voxels
    std::uint64_t streamlines = 0; ///< streamlines traced (both directions count as one)
    std::uint64_t samples = 0;     ///< integration samples taken (seed points included)
    std::uint64_t deposits = 0;    ///< fast: values deposited into voxels
    int rounds = 0;                ///< fast: seeding rounds
    double seconds = 0.0;          ///< wall-clock time of the convolution

    double samplesPerVoxel() const { return voxels ? double(samples) / double(voxels) : 0.0; }
};

/// Result: one float per output slot (see OutputDomain) and channel; inactive slots are 0.
struct LicResult
{
    std::vector<std::vector<float>> channels;
    LicStats stats;
};

/// Convolve `texture` (see NoiseTexture for the concept: kChannels and
/// `sample(outputIndexPos, float* out)`) along the streamlines of `field` for every active voxel
/// of `domain`. Deterministic: bit-identical results for any thread count.
/// @throw lic::InputError for invalid settings; lic::Cancelled if `progress` interrupts.
template<typename Texture>
LicResult convolve(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress = nullProgress());

namespace detail {
/// Ripple phase step per sample (cyclic animation): one period over the 2n+1 samples of a box
/// window.
inline double rippleStep(int n) { return 2.0 * 3.14159265358979323846 / double(2 * n + 1); }

/// Kernel-weighted window sums along one streamline of N samples with W values each (row-major
/// `vals`): `win` (N × W) gets each sample's weighted sum, `norm` (N) its total weight.
/// Box: samples i−n … i+n, clamped to the line. Exp: Σ_{k=0..n} c^k v_{i+k}, clamped, from the
/// backward recurrence E_i = v_i + c·E_{i+1}, sum_i = E_i − c^{n+1}·E_{i+n+1}: it only ever
/// multiplies by c < 1, so it does not drift however long the line (the forward recurrence of
/// the seed paper divides by c and does).
void windowSums(KernelType kernel, double decay, int n, std::size_t N, int W, const double* vals,
                double* win, double* norm, std::vector<double>& scratch);
/// World-space tracing parameters for a domain and settings; `maxSamples` = the kernel's.
TraceSettings traceSettings(const VelocityField& field, const OutputDomain& domain,
                            const LicSettings& settings);
} // namespace detail

} // namespace lic

#include "lic/FastLic.h"
#include "lic/NaiveLic.h"

namespace lic {

template<typename Texture>
LicResult convolve(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                   const LicSettings& settings, Progress& progress)
{
    settings.validate();
    if (settings.ripple) {
        return settings.engine == EngineType::Naive
                   ? naiveLic<Texture, true>(field, domain, texture, settings, progress)
                   : fastLic<Texture, true>(field, domain, texture, settings, progress);
    }
    return settings.engine == EngineType::Naive
               ? naiveLic(field, domain, texture, settings, progress)
               : fastLic(field, domain, texture, settings, progress);
}

} // namespace lic

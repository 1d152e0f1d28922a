// What a convolution is asked to do (LicSettings) and what it reports (LicStats), shared by every
// engine. Lengths are in OUTPUT VOXELS (the smallest edge of an output voxel) unless noted.
#pragma once

#include "lic/engine/Streamline.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"
#include "lic/util/Names.h"

#include <cstdint>
#include <span>
#include <string>

namespace lic {

/// The convolution engines; each has one row in the engine table (lic/engine/Engine.h), which
/// names it, says which inputs it takes and holds its policy and entry points.
enum class EngineType {
    Naive, ///< every voxel gathers along its own streamline (the reference)
    Fast,  ///< Stalling–Hege fast-LIC: long streamlines deposit into every voxel they cross
    Splat  ///< spots only: one streamline per spot, its footprint deposited around it (engine/Splat.h)
};

enum class KernelType {
    Box, ///< uniform weights over n samples each way
    Exp  ///< oriented: weights c^k over the n samples downstream (seed §7); bright heads point downstream
};
/// The engines' names (the engine table's names, lic/engine/Engine.h; a recipe's allowed values
/// besides "auto"). Inline, so that readers of recipes need not link the engines.
inline constexpr EnumName<EngineType> kEngineNames[] = {
    {EngineType::Naive, "naive"}, {EngineType::Fast, "fast"}, {EngineType::Splat, "splat"}};
inline std::span<const EnumName<EngineType>> engineNames() { return kEngineNames; }

/// The kernels' names (a recipe's allowed values).
inline constexpr EnumName<KernelType> kKernelNames[] = {{KernelType::Box, "box"}, {KernelType::Exp, "exp"}};
inline std::span<const EnumName<KernelType>> kernelNames() { return kKernelNames; }
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
    /// Also produce the ripple sums a cyclic animation is composed from (either kernel; see
    /// composite/Animation.h). The result then has 3·C + 2 channels.
    bool ripple = false;
    /// Spot loops of the splat and fast engines: this many frames of travelling comets (0 = none; see
    /// engine/Splat.h CometTables and docs/technique.md §8). The result then has comets · C channels,
    /// frame-major (frame f's channel c at f·C + c). Excludes `ripple`.
    int comets = 0;
    double length = 20.0;    ///< kernel half-length, one direction (> 0)
    double step = 0.5;       ///< arc length between samples (> 0, ≤ length)
    double tolerance = 1e-3; ///< RK45 local error per step
    int minHits = 2;         ///< fast: a voxel with fewer deposits seeds its own streamline
    int threads = 0;         ///< worker threads, 0 = all cores
    /// fast: a streamline stops after this many consecutive samples in voxels that were
    /// already covered (plus the kernel half-length it needs to finish its window).
    int coveredRun = 64;
    /// fast: longest streamline per direction in output voxels; 0 = automatic (see engine/Fast.h).
    double maxStreamline = 0.0;
    /// Brick edge in output voxels (a multiple of 8); 0 = the engine's own (see brickDim() in
    /// engine/Engine.h). The output depends on it (bricks seed their own streamlines), never on
    /// the thread count.
    int brick = 0;
    /// fast: samples per RK4 step (the integration step is stride · step; the samples in between
    /// are interpolated); 0 = automatic (see integrationStride() in engine/Engine.h).
    int stride = 0;

    /// Samples per direction of the kernel: round(length / step), at least 1.
    int halfSamples() const;
    /// Output channels for a texture of C channels: C, 3·C + 2 with the ripple sums, comets · C
    /// for a comet loop.
    int outputChannels(int textureChannels) const
    {
        if (comets > 0) return comets * textureChannels;
        return ripple ? 3 * textureChannels + 2 : textureChannels;
    }
    /// @throw lic::InputError naming the first out-of-range parameter.
    void validate() const;
};

/// Counters of one convolution, identical for any thread count.
struct LicStats
{
    std::uint64_t voxels = 0;      ///< active output voxels
    std::uint64_t streamlines = 0; ///< streamlines traced (both directions count as one)
    std::uint64_t samples = 0;     ///< integration samples taken (seed points included)
    std::uint64_t deposits = 0;    ///< fast and splat: values deposited into voxels
    std::uint64_t speculated = 0;  ///< fast: lines traced ahead, beside a line's last side
    std::uint64_t dropped = 0;     ///< fast: of those, lines dropped (their seed got covered)
    std::uint64_t bricks = 0;      ///< bricks convolved
    int brickDim = 0;              ///< brick edge, output voxels
    double seconds = 0.0;          ///< wall-clock time of the convolution

    /// Add another worker's or brick's counters (streamlines, samples, deposits, speculation).
    LicStats& operator+=(const LicStats& o)
    {
        streamlines += o.streamlines;
        samples += o.samples;
        deposits += o.deposits;
        speculated += o.speculated;
        dropped += o.dropped;
        return *this;
    }
    double samplesPerVoxel() const { return voxels ? double(samples) / double(voxels) : 0.0; }
};

namespace detail {
/// World-space tracing parameters for a domain and settings; `maxSamples` = the kernel's.
TraceSettings traceSettings(const VelocityField& field, const OutputDomain& domain, const LicSettings& settings);
/// Samples per RK4 step of the fast and splat engines: settings.stride, or automatically as many
/// as fit in about one field voxel (see docs/performance.md for the accuracy this keeps).
int integrationStride(const OutputDomain& domain, const LicSettings& settings);
} // namespace detail

} // namespace lic

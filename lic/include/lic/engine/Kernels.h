// Convolution kernels along one streamline: the window sums of the box and exp kernels, the
// ripple (periodic) weights of cyclic animation, and the peak a single spot gives. Shared by the
// engines; all lengths in samples or OUTPUT VOXELS.
#pragma once

#include "lic/engine/Settings.h"

#include <openvdb/math/Vec3.h>

#include <cstddef>
#include <vector>

namespace lic {

/// Largest value the convolution of one spot of radius `radius` (output voxels) can give on a
/// straight streamline through its centre with these kernel settings (all sub-sample phases
/// tried): the normalisation that maps a line's core to 1.
double spotPeak(const LicSettings& settings, double radius);

/// Comet loops (LicSettings::comets): the spacing P of the comets along a spot's streamline, in
/// output voxels: the kernel's extent (box 2·n·h, exp n·h) plus four times the reach of the widest
/// footprint `maxRadius` (a halo's radius), so that consecutive comets, halos included, stand apart
/// with a gap about their own width. Each comet moves P / frames output voxels per frame.
double cometSpacing(const LicSettings& settings, double maxRadius);
/// Amplitude of a comet copy at arc a of a train of spacing P: cos²(πa / 2P) for |a| < P, else 0.
/// The two copies inside (−P, P) at any phase sum to 1 (cos² + sin²), so a line carries the same
/// ink in every frame and comets fade in upstream and out downstream instead of popping.
double cometFade(double a, double spacing);
/// A spot's comet phase for N frames: a hash of its centre, so it does not depend on the order or
/// the subset of spots a process holds. Frame f (from 0) shows phase (f + phase) mod N, whose
/// copies sit at arcs (g/N − m)·P, m = 0, 1 (docs/technique.md §8).
int cometPhase(const openvdb::Vec3d& centre, int frames);

namespace detail {

/// Ripple period in samples (cyclic animation): one ripple per kernel window, the 2n+1 samples of
/// a box window or the n+1 of an exp one (downstream only). See composite/Animation.h and
/// docs/technique.md §8.
int ripplePeriod(const LicSettings& settings);
/// Ripple phase step per sample: one period over ripplePeriod() samples.
inline double rippleStep(const LicSettings& settings)
{
    return 2.0 * 3.14159265358979323846 / double(ripplePeriod(settings));
}

/// Kernel-weighted window sums along one streamline of N samples with W values each (row-major
/// `vals`): `win` (N × W) gets each sample's weighted sum, `norm` (N) its total weight.
/// Box: samples i−n … i+n, clamped to the line. Exp: Σ_{k=0..n} c^k v_{i+k}, clamped, from the
/// backward recurrence E_i = v_i + c·E_{i+1}, sum_i = E_i − c^{n+1}·E_{i+n+1}: it only ever
/// multiplies by c < 1, so it does not drift however long the line (the forward recurrence of
/// the seed paper divides by c and does).
void windowSums(KernelType kernel, double decay, int n, std::size_t N, int W, const double* vals, double* win,
                double* norm, std::vector<double>& scratch);

} // namespace detail
} // namespace lic

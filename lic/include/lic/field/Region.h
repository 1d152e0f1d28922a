// Regions of a field picked by a scalar: the smooth region-of-interest mask (seed §4) and the
// ridge "surface of interest" that spots are placed on (seed §5).
#pragma once

#include <openvdb/openvdb.h>

#include <algorithm>
#include <vector>

namespace lic {

/// Relative width of the ROI mask's soft edge: the mask falls from 1 to 0 over this fraction of
/// (hi − lo) just outside [lo, hi].
constexpr double kRoiSoftness = 0.05;

/// Region-of-interest weight of a scalar value: 1 for lo ≤ s ≤ hi, 0 beyond
/// kRoiSoftness·(hi − lo) outside, a C¹ smoothstep in between; 0 for NaN.
inline float roiWeight(double s, double lo, double hi)
{
    const double w = kRoiSoftness * (hi - lo);
    auto smooth = [](double t) {
        t = std::clamp(t, 0.0, 1.0);
        return t * t * (3.0 - 2.0 * t);
    };
    if (!(s == s)) return 0.0f;
    if (s < lo) return float(smooth(1.0 - (lo - s) / w));
    if (s > hi) return float(smooth(1.0 - (s - hi) / w));
    return 1.0f;
}

/// Points of the height ridge of a scalar above `threshold`, in WORLD space: at each active voxel
/// with s > threshold, the Hessian (central differences, index space) is diagonalised; where its
/// most negative eigenvalue λ < 0 (eigenvector e) and the Newton step to the maximum along e,
/// t = −(∇s·e)/λ, is at most half a voxel, the voxel lies on the ridge and the point
/// x + t·e is returned (sub-voxel). Voxels without all 26 active neighbours are skipped.
/// Deterministic order (leaf order, then voxel order).
std::vector<openvdb::Vec3d> ridgePoints(const openvdb::FloatGrid& scalar, double threshold);

/// |∇s| of a scalar grid, world units (OpenVDB's gradient and magnitude tools), named `name`:
/// ridges of |∇speed| are the thin layers between fast and slow flow.
openvdb::FloatGrid::Ptr gradientMagnitude(const openvdb::FloatGrid& scalar, const std::string& name);

} // namespace lic

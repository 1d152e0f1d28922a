// Scalar grids for colouring a bake: quantities derived from the velocity field (speed,
// vorticity, helicity, Q-criterion) or float grids stored in the field file.
#pragma once

#include <openvdb/openvdb.h>

#include <map>
#include <string>
#include <vector>

namespace lic {

/// Names of the derived scalars, in a stable order:
/// - "speed": |v| (world units per unit time);
/// - "vorticity": |ω|, ω = curl v (1 / time);
/// - "streamwise-vorticity": ω·v/|v|, 0 where |v| = 0 (1 / time);
/// - "helicity": v·ω (world units / time²);
/// - "q-criterion": Q = ½(‖Ω‖² − ‖S‖²) with S and Ω the symmetric and antisymmetric parts of the
///   velocity gradient ∇v and ‖·‖ the Frobenius norm (1 / time²). Q > 0 where rotation dominates
///   strain; solid-body rotation at angular speed w has Q = w²;
/// - "lambda2": λ2 of Jeong & Hussain, the middle eigenvalue of S² + Ω² (1 / time²); negative in
///   vortex cores (solid-body rotation at w: −w²).
const std::vector<std::string>& derivedScalarNames();

/// Compute the derived scalar @a name on the velocity grid's own voxels.
///
/// The result is a FloatGrid named @a name, grid class UNKNOWN, with the velocity grid's transform
/// and exactly its active topology, every active value in a leaf voxel (active tiles of the input
/// are voxelized); inactive voxels hold 0. Velocity values are world-space vectors; derivatives
/// are taken in WORLD units through the grid's transform (any linear or non-linear map, via the
/// map's inverse Jacobian), so they scale correctly with the voxel size.
///
/// Differences: second-order central differences in index space along each axis where both
/// neighbours are active; at the active boundary, the second-order one-sided difference where two
/// active neighbours lie on one side, else the first-order one, else 0 for that axis (an isolated
/// voxel). Inactive voxels are never read as data, so the boundary carries no zero-velocity
/// artefact; all differences are exact for fields linear in index space.
/// Staggered grids (GRID_STAGGERED, component c of voxel ijk on the face at ijk − ½e_c, as in
/// VelocityField) are first averaged to voxel centres, ½(v_c(ijk) + v_c(ijk + e_c)), taking
/// v_c(ijk) alone where ijk + e_c is inactive.
///
/// Multithreaded (TBB); deterministic.
/// @throw lic::InputError for an unknown @a name (the message lists derivedScalarNames() and
///        says that a float grid of the field file can also be named).
openvdb::FloatGrid::Ptr deriveScalar(const openvdb::Vec3SGrid& velocity, const std::string& name);

/// Resolve a scalar by name: a derived scalar computed by deriveScalar(), or else the float grid
/// of @a fileScalars with that name (keys are grid names), returned as is (not copied, not
/// resampled). Derived names take precedence: a file grid called e.g. "speed" is shadowed.
/// @throw lic::InputError if @a name is neither (the message lists both kinds of valid names).
openvdb::FloatGrid::ConstPtr resolveScalar(
    const openvdb::Vec3SGrid& velocity,
    const std::map<std::string, openvdb::FloatGrid::Ptr>& fileScalars, const std::string& name);

} // namespace lic

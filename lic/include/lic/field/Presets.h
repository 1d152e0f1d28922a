// Analytic example vector fields ("presets") baked into OpenVDB grids, for demos, tests
// and `licvdb field PRESET --res X,Y,Z --out FIELD.vdb`.
#pragma once

#include <openvdb/openvdb.h>

#include <string>
#include <vector>

namespace lic {

/// An analytic example field: `velocity` (Vec3SGrid) plus scalar grids where the preset
/// has them (e.g. `temperature` for `tabbed-jet`).
///
/// Grid conventions (all grids of one PresetField share them):
/// - index space (0,0,0)..(res-1), every voxel of that box active and stored as a leaf
///   voxel (no active tiles: Blender 3.4 renders tiles as empty), background zero;
/// - one linear transform with a uniform voxel size h (world units): the voxel centres of
///   the longest axis span exactly the preset's reference extent, h = extent/(maxRes-1),
///   the other axes use the same h, and the box is centred on the preset's centre;
/// - `velocity` holds world-space vectors (world units per unit time):
///   vector type VEC_CONTRAVARIANT_RELATIVE, isInWorldSpace() true, grid class unknown;
/// - every grid carries string metadata `licvdb_preset` with the preset name.
/// - scalar grids carry string metadata `units` ("K" for temperature), grid class unknown.
struct PresetField
{
    openvdb::Vec3SGrid::Ptr velocity;              ///< named "velocity"
    std::vector<openvdb::FloatGrid::Ptr> scalars;  ///< e.g. "temperature" (kelvin) for tabbed-jet
};

/// The preset names in a stable order:
/// uniform, rotation, abc, saddle, tornado, vortex-ring, tabbed-jet.
std::vector<std::string> presetNames();

/// A one-line description of the preset, for `licvdb help field`.
/// @throw lic::InputError for an unknown name (the message lists the valid names).
std::string presetDescription(const std::string& name);

/// The preset's default resolution in voxels: 101,101,148 for tabbed-jet, 64,64,64 otherwise.
/// @throw lic::InputError for an unknown name (the message lists the valid names).
openvdb::Coord presetDefaultResolution(const std::string& name);

/// Bake the analytic field @a name on a grid of @a resolution voxels (x, y, z), evaluating
/// the formula at each voxel centre's world position. Multithreaded (TBB) and
/// deterministic: every value is a pure function of its voxel's position.
/// Calls openvdb::initialize().
/// @throw lic::InputError for an unknown name (the message lists the valid names), or a
///        resolution outside [2, 2048] on any axis, or more than 2^30 voxels in total.
/// @a time: the moment of an unsteady preset (in the field's time unit: velocity is world units
/// per time unit). Only `tornado` changes with time (Crawfis's funnel centre precesses, at
/// 1 and 0.75 radians per time unit); the others are steady. Grids of a time other than 0 carry
/// float metadata `licvdb_time`.
PresetField makePresetField(const std::string& name, const openvdb::Coord& resolution, double time = 0.0);

/// True for the presets whose velocity changes with time.
bool presetIsUnsteady(const std::string& name);

} // namespace lic

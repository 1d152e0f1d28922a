// Stage 2 of a bake: the field, the output domain, its bricks and this process's share of them.
//
// One process reads the whole field. In a distributed bake each rank reads only the part its
// bricks need where the format allows it: for a .vdb field whose velocity is a vec3s grid, the
// grid's topology first (delayed loading: value masks, no values) gives the whole output domain
// and brick layout; then the velocity and the file's float grids are read clipped to the rank's
// bricks grown by the distance any trace or stencil can reach (fieldMargin()). Everything that
// must be the whole field's — the domain, the active bounding box that bounds streamlines, the
// zero-velocity threshold (from the largest speed, a maximum over the ranks) — is, so the result
// is bit-identical to one process. Other formats and recipes that need the whole field at once
// (crop, resample, mask, nan_policy zero, surface spots) are read whole on every rank.
#pragma once

#include "Plan.h"

#include "vdbexport/io/FieldInput.h"

#include "lic/field/Bricks.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"

#include <memory>
#include <string>
#include <vector>

namespace vdbexport::pipeline {

struct FieldShare
{
    LoadedField loaded;                         ///< velocity and file scalars: whole, or this rank's part
    std::unique_ptr<lic::VelocityField> field;  ///< made by readFieldShare (whole) or makeField (part)
    std::unique_ptr<lic::OutputDomain> domain;  ///< the whole bake's
    std::unique_ptr<lic::BrickLayout> layout;   ///< every brick
    std::vector<int> assignment;                ///< rank of each brick (by id)
    std::vector<std::size_t> mine;              ///< this rank's bricks, ascending ids
    bool partial = false;                       ///< only a part of the field was read
    std::string wholeReason;                    ///< why the whole field was read (distributed bakes)
    lic::FieldExtent extent;                    ///< partial: the whole field (maxSpeed: this part's until makeField)
    std::uint64_t voxelsHeld = 0;               ///< field voxels of the dense velocity copy here
};

/// Output voxels from a process's bricks within which a spot centre can change one of its voxels:
/// for the gather engines a voxel's window (the ghost margin) meets the spot's largest halo; for
/// splat the spot's own line (n·h + R each way) and its footprint around it reach the brick.
double spotReach(const Plan& plan);

/// Field voxels (per side) by which a rank's part reaches past its bricks: the ghost margin, one
/// integration step past the last sample (RK4 with stride, or RK45's largest step), the spot
/// reach, the trilinear footprint, staggered neighbours, and (when the recipe uses scalars) the
/// finite-difference stencils of derived scalars and their gradients. `stride`: samples per RK4
/// step (lic::detail::integrationStride).
int fieldMargin(const Plan& plan, int upsample, int stride);

/// Read the field and make the domain, the brick layout and the share of `rank` out of `ranks`.
/// With `ranks` > 1 and a field that allows it, only the part is read and `field` is left for
/// makeField(). `whole`: a reason to read the whole field on every rank anyway; `extra`: field
/// voxels added to a part's margin (an unsteady sequence's texture reaches further). Local to
/// this process (no communication).
/// @throw lic::InputError for a bad field (see loadField()).
FieldShare readFieldShare(const Plan& plan, int rank, int ranks, const std::string& whole = "", int extra = 0);

/// The VelocityField of a part, once the ranks agreed on the whole field's largest speed.
/// @throw lic::InputError for NaN or infinite values in the part.
void makeField(FieldShare& share, double maxSpeed);

} // namespace vdbexport::pipeline

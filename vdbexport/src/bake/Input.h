// Stage 4 of a bake: the input texture. Noise is made brick by brick (with the brick's ghost
// margin, and the region-of-interest pre-mask applied there); spots are placed once for the
// whole volume (their count grows with the volume over spacing³, not with the voxels).
#pragma once

#include "Plan.h"
#include "Scalars.h"

#include "lic/Noise.h"
#include "lic/OutputDomain.h"
#include "lic/Spots.h"

#include <memory>

namespace vdbexport::pipeline {

struct Input
{
    lic::SpotSet spots;                            ///< spot bakes: centres (output index) and weights
    std::unique_ptr<lic::NoiseBrickSource> noise;  ///< noise bakes: per-brick noise
};

/// @throw lic::InputError for a surface scalar without ridges above its threshold.
Input makeInput(const Plan& plan, const lic::OutputDomain& domain, ScalarSet& scalars);

} // namespace vdbexport::pipeline

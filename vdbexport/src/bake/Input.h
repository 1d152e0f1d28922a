// Stage 4 of a bake: the input texture. Noise is made brick by brick (with the brick's ghost
// margin, and the region-of-interest pre-mask applied there); spots are placed once for the
// whole volume (their count grows with the volume over spacing³, not with the voxels).
#pragma once

#include "Plan.h"
#include "lic/field/ScalarField.h"

#include "lic/texture/Noise.h"
#include "lic/field/OutputDomain.h"
#include "lic/texture/Spots.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace vdbexport::pipeline {

struct Input
{
    lic::SpotSet spots;                            ///< spot bakes: centres (output index) and weights
    std::uint64_t spotCount = 0;                   ///< spot bakes: spots of this process's bricks
    std::uint64_t seedsRead = 0;                   ///< input.seeds: points in the file (0 without seeds)
    /// input.seeds: points whose nearest output voxel is not an active voxel of the output domain
    /// (dropped; the whole bake's count on every process)
    std::uint64_t seedsDropped = 0;
    std::unique_ptr<lic::NoiseBrickSource> noise;  ///< noise bakes: per-brick noise
};

/// A process's part of a distributed spot bake: it keeps only the spots that can touch its
/// bricks (their textures are summed per cell in spot order, so dropping spots that add nothing
/// leaves every value the same), and counts those whose centre lies in its own blocks.
struct SpotShare
{
    openvdb::BBoxd reach;            ///< output index space: spots outside cannot touch the bricks
    std::vector<bool> ownBlocks;     ///< per domain block: one of this process's bricks holds it
};

/// The spots of `all` (in order) that a process with `share` keeps; `owned` counts those whose
/// centre lies in its own blocks.
lic::SpotSet spotsOfShare(const lic::SpotSet& all, const lic::OutputDomain& domain, const SpotShare& share,
                          std::uint64_t& owned);

/// `share`: null for the whole bake (one process).
/// @throw lic::InputError for a surface scalar without ridges above its threshold, or a bad
///        seeds file (input.seeds, vdbexport/io/SeedPoints.h).
/// `raw`: the noise bake's per-voxel white noise when it is not the seed's (an unsteady
/// sequence's carried noise, lic/texture/Advection.h).
Input makeInput(const Plan& plan, const lic::OutputDomain& domain, lic::ScalarSet& scalars, const SpotShare* share = nullptr,
                lic::NoiseTexture::RawNoise raw = {});

} // namespace vdbexport::pipeline

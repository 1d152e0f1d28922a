// Stage 1 of a bake: the plan. Everything that follows from the recipe alone (engine settings,
// which channels and grids the bake makes), decided and validated once, before any file is read.
#pragma once

#include "vdbexport/bake/Recipe.h"

#include "lic/engine/Settings.h"

#include <string>
#include <vector>

namespace vdbexport::pipeline {

struct Plan
{
    const Recipe& recipe;
    lic::LicSettings settings;
    int frames = 1;         ///< cyclic loop frames (1 = a still)
    bool spots = false;     ///< spot input (else noise)
    bool roiPre = false, roiPost = false;
    bool stretch = true;    ///< contrast stretch (noise) / peak normalisation (spots)
    int levels = 1;         ///< spot radius levels K
    int textureChannels = 1;///< C: 1 for noise, 2K for spots (lines, then halos)
    int rawChannels = 1;    ///< channels a brick delivers: C, 3C + 2 for a ripple loop, frames · C for comets
    /// Spots: the peak a single spot gives on a straight line, per level (lines and halos), the
    /// normalisation that maps a line's core to 1 (1 without stretch).
    std::vector<double> linePeak, haloPeak;
    /// Spots: the largest halo radius (output voxels), how far a spot's texture reaches.
    double maxSpotRadius = 0.0;
};

/// The directory an output path writes into: its parent, or "." for a bare file name.
std::string outputDirectory(const std::string& out);

/// Validate the recipe (values, paths, combinations, features not available yet) and plan the
/// bake. @throw lic::InputError naming the first problem.
Plan makePlan(const Recipe& recipe);

/// Refuse `lic` keys set to other than their defaults that nothing will read: keys the chosen
/// engine (for "auto", the one it picks) does not read (lic::EngineInfo::keys), lic.decay without
/// the exp kernel, lic.tolerance without rk45 (bake/EngineKeys.cpp; makePlan() calls it).
/// @throw lic::InputError naming the keys, the engine and the keys it reads.
void checkEngineKeys(const Recipe& recipe);

} // namespace vdbexport::pipeline

// The convolution engines: one table that names each engine, says which inputs it takes and holds
// its policy (brick size, how far past a brick it reaches) and its entry points; and the calls a
// bake makes, which dispatch through it. Everything a caller needs to know about an engine is
// asked here: no other layer re-derives an engine's geometry.
//
// Adding an engine: its files in lic/engine/, a value in EngineType (engine/Settings.h) and one
// row of the table (src/engine/Engine.cpp), which also names the recipe keys it reads; a gather
// engine (one that samples a texture along streamlines, engine/Gather.h) also goes into
// GatherEngines there.
#pragma once

#include "lic/engine/Driver.h"
#include "lic/engine/Settings.h"
#include "lic/field/Bricks.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"
#include "lic/util/Progress.h"

#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace lic {

class NoiseBrickSource; // texture/Noise.h
struct SpotSet;         // texture/Spots.h

/// A convolution over some bricks: the field, the output domain, the bricks to convolve (a
/// whole layout, or one process's share of it) and the settings.
struct ConvolveJob
{
    const VelocityField& field;
    const OutputDomain& domain;
    const BrickLayout& layout;
    const LicSettings& settings;
    Progress& progress;
};

/// A spot input: centres and weights, the line radii r_k (output voxels, 1 to 4 levels) and the
/// halo radius factor; the texture's channels are the lines, then the halos.
struct SpotInput
{
    const SpotSet& spots;
    const std::vector<double>& radii;
    double haloScale = 2.0;
    /// Largest halo radius, output voxels: how far a spot's texture reaches from its centre.
    double maxRadius() const;
};

/// One row of the engine table.
struct EngineInfo
{
    EngineType type;
    const char* name;
    const char* summary; ///< one line, for help texts
    /// The recipe's `lic` keys this engine reads besides `engine`, by their recipe names
    /// (docs/recipe.md): a bake refuses a recipe that sets any other (vdbexport's
    /// bake/EngineKeys.cpp, which must know each name).
    std::span<const std::string_view> keys;
    /// The brick edge when the settings do not set one (output voxels): a function of the
    /// settings only, never of the thread count, so the output never depends on the machine.
    int (*defaultBrick)(const LicSettings&);
    /// Output voxels from a brick's box within which a spot centre can change one of its voxels.
    double (*spotReach)(const LicSettings&, double maxSpotRadius);
    /// Output voxels past a brick's box at which convolving the brick samples the field
    /// (`spots`: spot input; `stride`: samples per RK4 step, integrationStride()).
    double (*fieldReach)(const LicSettings&, bool spots, double maxSpotRadius, int stride);
    /// Convolve per-brick noise; null when the engine takes no noise.
    LicStats (*noiseBricks)(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);
    /// Convolve a spot texture; null when the engine takes no spots.
    LicStats (*spotBricks)(const ConvolveJob&, const SpotInput&, const BrickSink&);
};

/// Every engine, in the order `licvdb help bake` lists them.
std::span<const EngineInfo> engines();
/// The row of an engine.
const EngineInfo& engineInfo(EngineType type);
const char* toString(EngineType);
/// @throw lic::InputError for a name not in the table (the message lists the table).
EngineType engineFromString(const std::string&);
/// The engine a recipe's name means: "auto" is splat for spots and fast for noise; any other
/// name as engineFromString().
/// @throw lic::InputError for an unknown name, or an engine that does not take this input
///        (the message names the engines that do).
EngineType chooseEngine(const std::string& name, bool spots);

/// The brick edge of these settings: settings.brick, or the engine's own (output voxels).
int brickDim(const LicSettings& settings);
/// Ghost margin of a brick (output voxels per side): how far outside its box a streamline traced
/// for the brick can sample the input texture (the kernel length, the half voxel of nearest-voxel
/// rounding and the trilinear/binomial footprint). The per-brick noise is made this far out.
int ghostMargin(const LicSettings& settings);
/// engineInfo(settings.engine).spotReach: how far from a brick a spot can change it.
double spotReach(const LicSettings& settings, double maxSpotRadius);
/// engineInfo(settings.engine).fieldReach: how far past a brick the field is sampled.
double fieldReach(const LicSettings& settings, bool spots, double maxSpotRadius, int stride);

/// Convolve per-brick noise over `job.layout`, each brick handed to `sink` as it finishes.
/// Deterministic: every brick's channels are bit-identical for any thread count.
/// @throw lic::InputError for invalid settings or an engine that takes no noise; lic::Cancelled.
LicStats convolveNoiseBricks(const ConvolveJob& job, NoiseBrickSource& noise, const BrickSink& sink);
/// Convolve a spot texture (2K channels, lines then halos, or their ripple sums) over
/// `job.layout`. Bricks no spot reaches may be skipped (they have nothing to show).
/// @throw lic::InputError for invalid settings or radii (1 to 4 levels); lic::Cancelled.
LicStats convolveSpotBricks(const ConvolveJob& job, const SpotInput& spots, const BrickSink& sink);

/// Result of a whole-volume convolution: one float per output slot (see OutputDomain) and
/// channel; inactive slots are 0.
struct LicResult
{
    std::vector<std::vector<float>> channels;
    LicStats stats;
};

/// convolveSpotBricks() over the whole domain, into one array per channel: for tests and small
/// volumes (a bake streams bricks instead).
LicResult convolveSpots(const VelocityField& field, const OutputDomain& domain, const SpotSet& spots,
                        const std::vector<double>& radii, double haloScale, const LicSettings& settings,
                        Progress& progress = nullProgress());

namespace detail {
/// Gather a brick's channels into whole-volume arrays (convolve(), convolveSpots()).
void copyBrick(const BrickChannels& bc, std::vector<std::vector<float>>& channels);
} // namespace detail

} // namespace lic

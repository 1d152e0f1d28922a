// A bake recipe: every setting of one `licvdb bake`, with defaults, read from JSON,
// validated, and written back as the fully resolved JSON stored in the output's metadata.
//
// The JSON keys are snake_case as in docs/recipe.md; the struct members are
// camelCase. Lengths (`lic.length`, `lic.step`, `input.spacing`, `input.radii`) are in
// output voxels, i.e. field voxels times `output.upsample`.
#pragma once

#include "vdbexport/io/FieldSpec.h"

#include "lic/composite/OutputGrids.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport {

/// Where and what to write (JSON `output`).
struct OutputSpec
{
    std::string path;            ///< `path`: output .vdb; may be empty until the CLI sets it
    int upsample = 2;            ///< `upsample`: output voxels per field voxel, [1, 16]
    std::string contrast = "stretch"; ///< `contrast`: "stretch" | "none"
    /// The grids asked for by the `write_*` keys (`write_input`, `write_tangent`, `write_velocity`,
    /// `write_series`): the output-grid table's rows asked for by a recipe key
    /// (lic/composite/OutputGrids.h), so a new grid adds its key there.
    lic::OutputGridSet grids;
    bool writes(lic::OutputGrid g) const { return grids.has(g); }
    /// `half`: store float and vec3s grids as 16-bit halves on disk (about half the file;
    /// readers get float grids back, to ~5e-4 relative)
    bool half = false;

    bool operator==(const OutputSpec&) const = default;
};

/// Spots are placed on the ridge surface of a scalar (JSON `input.surface`).
struct SurfaceSpec
{
    std::string scalar;     ///< `scalar`: scalar name (speed, vorticity, ... or a float grid)
    double threshold = 0;   ///< `threshold`: in the scalar's own units

    bool operator==(const SurfaceSpec&) const = default;
};

/// The input texture (JSON `input`).
struct InputSpec
{
    std::string type = "noise";           ///< `type`: "noise" | "spots"
    std::string distribution = "poisson"; ///< `distribution`: "regular" | "random" | "jittered" | "poisson"
    double spacing = 6;                   ///< `spacing`: spot spacing, output voxels, > 0
    double jitter = 0.25;                 ///< `jitter`: max offset as a fraction of spacing, [0, 1]
    std::vector<double> radii{1.0};       ///< `radii`: spot radii, output voxels, > 0, strictly increasing
    double haloScale = 2.0;               ///< `halo_scale`: halo radius / spot radius, >= 1
    std::uint64_t seed = 1;               ///< `seed`: hash seed for noise and spot positions
    std::string noiseFilter = "binomial"; ///< `noise_filter`: "binomial" (3³ low-pass) | "none"
    std::optional<SurfaceSpec> surface;   ///< `surface`: null = spots fill the volume
    /// `seeds`: a file of spot centres in world units (.npy (N, 3) float32/float64, or text
    /// `x y z` lines); "" = none. Replaces `distribution` (then `distribution`, `spacing` and
    /// `jitter` are ignored); not with `surface`
    std::string seeds;

    bool operator==(const InputSpec&) const = default;
};

/// Region of interest from a scalar (JSON `roi`).
struct RoiSpec
{
    std::string scalar;                 ///< `scalar`: scalar name
    std::array<double, 2> range{0, 1};  ///< `range`: [lo, hi] kept, in the scalar's units, lo < hi
    std::string mode = "pre";           ///< `mode`: "pre" (mask the input) | "post" (mask the output)

    bool operator==(const RoiSpec&) const = default;
};

/// The convolution (JSON `lic`).
struct LicSpec
{
    /// `engine`: "auto" (lic::chooseEngine picks by the input) or a name of the engine table
    /// (lic/engine/Engine.h engines()); a bake records the engine it used
    std::string engine = "auto";
    std::string kernel = "box";      ///< `kernel`: "box" | "exp"
    double length = 20;              ///< `length`: kernel half-length (one direction), output voxels, (0, 10000]
    double step = 0.5;               ///< `step`: sample spacing along the streamline, output voxels, (0, length]
    double decay = 0.9;              ///< `decay`: exp kernel factor c per step, (0, 1)
    std::string integrator = "rk4";  ///< `integrator`: "rk4" | "rk45"
    double tolerance = 1e-3;         ///< `tolerance`: rk45 error tolerance, > 0
    int minHits = 2;                 ///< `min_hits`: fast-LIC deposits before a voxel is no seed, [1, 64]
    /// `brick`: brick edge in output voxels, a multiple of 8 in [8, 512]; 0 = automatic (64 for
    /// kernels up to 24 voxels, else 128). The output depends on it, never on threads.
    int brick = 0;

    bool operator==(const LicSpec&) const = default;
};

/// Line width chosen per voxel by a scalar (JSON `width`).
struct WidthSpec
{
    std::string scalar;                          ///< `scalar`: scalar name
    std::optional<std::array<double, 2>> range;  ///< `range`: [lo, hi]; nullopt = "auto" (data range)
    bool invert = false;                         ///< `invert`: high scalar = thin lines

    bool operator==(const WidthSpec&) const = default;
};

/// Colour by a scalar (JSON `color`).
struct ColorSpec
{
    std::string scalar;                          ///< `scalar`: scalar name
    std::string colormap = "viridis";            ///< `colormap`: colormap name
    std::optional<std::array<double, 2>> range;  ///< `range`: [lo, hi]; nullopt = "auto" (data range)

    bool operator==(const ColorSpec&) const = default;
};

/// Cyclic animation (JSON `animation`).
struct AnimationSpec
{
    int frames = 1; ///< `frames`: frames in the loop, [1, 10000]; 1 = a single still bake

    bool operator==(const AnimationSpec&) const = default;
};

/// All settings of one bake. Default-constructed = the defaults in docs/recipe.md.
struct Recipe
{
    FieldSpec field;
    OutputSpec output;
    InputSpec input;
    std::optional<RoiSpec> roi;
    LicSpec lic;
    std::optional<WidthSpec> width;
    std::optional<ColorSpec> color;
    AnimationSpec animation;
    int threads = 0; ///< `threads`: worker threads, [0, 1024]; 0 = all cores

    bool operator==(const Recipe&) const = default;

    /// The fully resolved recipe: every key with its value. Absent optional sections
    /// (`roi`, `width`, `color`, `input.surface`) are null; an automatic range is "auto".
    nlohmann::json toJson() const;

    /// Read a recipe from JSON, merging the keys present onto the defaults. Does not call
    /// validate(). `source` (a file name, or "recipe") starts every error message.
    /// @throw lic::InputError on an unknown key (naming its full path and the nearest valid
    ///        key) or a value of the wrong type (naming the key path and the expected type).
    static Recipe fromJson(const nlohmann::json& j, const std::string& source = "recipe");

    /// Check every value's range and every enumerated value; paths are not checked
    /// (see validatePaths()).
    /// @throw lic::InputError "<key path>: must be <rule> (got <value>)" at the first violation.
    void validate() const;

    /// Require `field.path` and `output.path`, which the CLI may supply (--field / --out).
    /// @throw lic::InputError naming the missing key and the flag that sets it.
    void validatePaths() const;
};

/// Parse recipe JSON text, then fromJson() and validate().
/// @throw lic::InputError on malformed JSON ("<source>: invalid JSON at line L, column C: ..."),
///        an unknown key, a wrong type, or a value out of range (prefixed by `source`).
Recipe parseRecipe(const std::string& text, const std::string& source = "recipe");

/// Read the file at `path`, then parseRecipe(text, path).
/// @throw lic::InputError if the file cannot be read, or as parseRecipe().
Recipe loadRecipeFile(const std::string& path);

/// The allowed values of an enumerated key ("lic.engine", "lic.kernel", "lic.integrator",
/// "input.type", "input.distribution", "roi.mode", "output.contrast", "field.format",
/// "field.dtype", "field.mask", "field.nan_policy"); empty for other keys.
const std::vector<std::string>& allowedValues(const std::string& keyPath);

/// The entry of `valid` nearest to `bad` by edit distance (case-insensitive, a transposition
/// counts as one edit), or "" if none is close enough to be a plausible typo.
std::string suggestKey(const std::string& bad, const std::vector<std::string>& valid);

} // namespace vdbexport

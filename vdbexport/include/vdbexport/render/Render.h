// `licvdb render`: read a baked .vdb (or a sequence, or a bake's manifest), raycast it with
// lic::HaloRaycaster and write images (EXR scene-linear, PNG/JPEG/TIFF/GIF through OCIO).
#pragma once

#include "vdbexport/io/ImageIO.h"

#include <lic/util/Progress.h>
#include <lic/render/Raycaster.h>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport {

/// How a render settles its density window (`--density-range`).
enum class DensityRangeMode
{
    ByBake, ///< default: automatic (autoDensityRange) for a dense noise bake (`density` metadata
            ///< lic_input = "noise"), else settings.densityLow/High (0,1)
    Auto,   ///< `--density-range auto`: automatic for any file
    Fixed,  ///< `--density-range LO,HI`: settings.densityLow/High as given
};

/// Everything `licvdb render` does, as values.
struct RenderJob
{
    std::string input;  ///< a .vdb, the first frame OUT_0001.vdb of a sequence, or a bake manifest .json
    std::string output; ///< image path; its extension picks the format
    std::optional<lic::View> view;      ///< default front
    std::optional<double> azimuth;      ///< degrees; overrides the view's
    std::optional<double> elevation;    ///< degrees; overrides the view's
    lic::CameraSettings camera;         ///< size, fov, ortho, distance (azimuth/elevation set from the above)
    lic::RenderSettings settings;       ///< densityLow/High give way to the automatic window when densityRange picks it
    DensityRangeMode densityRange = DensityRangeMode::ByBake;
    std::string colormap;               ///< over `scalar`; empty = `color` grid or white
    std::string field;                  ///< velocity .vdb for the tangent when there is no `tangent` grid
    lic::StereoMode stereo = lic::StereoMode::None;
    std::optional<double> eyeSeparation; ///< world units; default distance / 30
    int frames = 0;                     ///< 0 = a still (or all files of a manifest)
    bool gif = false;                   ///< also write an animated OUT.gif of a sequence
    double fps = 12.0;                  ///< GIF frame rate
    std::string viewTransform = "standard";
    std::string ocioConfig;             ///< explicit config path (else findOcioConfig)
};

/// Command-line values that need parsing (empty = not given), applied by applyRenderFlags.
struct RenderFlagStrings
{
    std::string size;         ///< "W,H" or "N" (square)
    std::string view;         ///< front|back|left|right|top|bottom
    std::string halos;        ///< on|off
    std::string light;        ///< "headlight" or "X,Y,Z" (direction towards the light)
    std::string densityRange; ///< "LO,HI" or "auto"
    std::string stereo;       ///< sbs|anaglyph|none
};

/// @brief Parse `flags` into `job`. @throw lic::InputError naming the flag, the bad value and
///        what was expected.
void applyRenderFlags(RenderJob& job, const RenderFlagStrings& flags);

/// The density window `--density-range auto` chooses from a `density` grid.
struct AutoDensityRange
{
    double low = 0.0, high = 1.0;
    std::uint64_t voxels = 0;     ///< active voxels with density > 0, which the percentiles are of
    bool fromPercentiles = false; ///< false: the percentiles gave no window, it is 0 to the max
};

/// Percentiles of the active voxels' density (> 0) that bound the automatic window.
inline constexpr double kAutoDensityLowPercentile = 90.0;
inline constexpr double kAutoDensityHighPercentile = 99.9;

/// @brief The automatic density window of `density`: low = the kAutoDensityLowPercentile-th and
///        high = the kAutoDensityHighPercentile-th percentile of the density of the active voxels
///        with density > 0 (a 65536-bin histogram over [0, max], interpolated in the bin, rounded
///        to 10⁻⁴), so that only the brightest tenth of a dense noise texture — the cores of its
///        streaks — is visible. Deterministic. When that gives no window the renderer accepts
///        (no voxel > 0, all equal, or low ≥ 1), it is 0 to the largest density (0,1 if none).
AutoDensityRange autoDensityRange(const openvdb::FloatGrid& density);

/// The image of frame `frame` (1-based) of `frames`: IMAGE.png for a still, IMAGE_0001.png … for
/// a sequence (4 digits).
std::string imageFramePath(const std::string& imagePath, int frame, int frames);

/// @brief The .vdb files a render reads: a manifest's `files` (relative to the manifest), or
///        for `frames` > 1 the sequence IN_0001.vdb … (IN may be given as its first frame
///        OUT_0001.vdb or as OUT.vdb), or just `input`.
/// @throw lic::InputError for a bad manifest, a missing frame, or `frames` that contradicts the
///        manifest.
std::vector<std::string> renderInputs(const std::string& input, int frames);

/// The camera as JSON: position, forward, up, right, target, projection, fov_y_degrees and
/// fov_x_degrees (perspective), ortho_width/ortho_height (orthographic), image_size, azimuth,
/// elevation, distance, and a `blender` block (matrix_world, rotation_euler XYZ in radians,
/// type, sensor_fit, angle_y, ortho_scale, resolution) that reproduces it in Blender.
nlohmann::json cameraJson(const lic::Camera& camera);

/// @brief Run the job: read, render every frame (and eye), write the images atomically.
/// @return the summary `licvdb render --json` prints (camera(s), output paths, seconds).
/// @throw lic::InputError for bad input (missing or non-VDB file, no `density` grid — the
///        message lists the grids the file has —, bad settings, unwritable output);
///        lic::Cancelled; lic::Error for runtime failures. Images already written by a failed
///        sequence are removed.
nlohmann::json render(const RenderJob& job, lic::Progress& progress = lic::nullProgress());

} // namespace vdbexport

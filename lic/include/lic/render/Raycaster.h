// The reference halo raycaster (seed §6): front-to-back emission–absorption raymarching of the
// line (`density`) and halo (`halo`) volumes together, with illuminated lines (Zöckler, Stalling &
// Hege 1996). Works on in-memory grids and produces a scene-linear RGBA float image
// (render/Image.h) of a camera (render/Camera.h); file I/O lives in vdbexport.
#pragma once

#include "lic/composite/Colormap.h"
#include "lic/render/Camera.h"
#include "lic/render/Image.h"
#include "lic/util/Progress.h"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <utility>

namespace lic {

// ---- the volume and the transfer function ---------------------------------------------------

/// The grids a render reads (world-space grids; all optional but `density`). Grids may have
/// different transforms: the others are resampled onto `density`'s voxels (trilinear, into a new
/// sparse grid). The raycaster keeps (shares) the grids it reads where they are, without copying
/// them: they must not be modified while it lives.
struct RenderVolume
{
    openvdb::FloatGrid::ConstPtr density; ///< lines, [0, 1]; required
    openvdb::FloatGrid::ConstPtr halo;    ///< halo texture, [0, 1]; halo ≥ density on the lines
    openvdb::Vec3SGrid::ConstPtr color;   ///< scene-linear Rec.709
    openvdb::FloatGrid::ConstPtr scalar;  ///< [0, 1], coloured through RenderSettings::colormap
    openvdb::Vec3SGrid::ConstPtr tangent; ///< unit flow direction (world)
    openvdb::Vec3SGrid::ConstPtr flow;    ///< velocity field: the tangent where `tangent` is absent
};

/// Directional lighting of lines (Zöckler et al. 1996). With T the unit line tangent, L the
/// unit direction towards the light and V the unit direction towards the eye:
/// diffuse = √(1 − (L·T)²), V·R = √(1 − (L·T)²)·√(1 − (V·T)²) − (L·T)(V·T), and
/// shade = colour·(ambient + diffuse·diffuse-term) + specular·max(V·R, 0)^shininess.
struct Lighting
{
    bool enabled = true;     ///< false (or no tangent): shade = colour
    bool headlight = true;   ///< L = V (a light at the eye)
    openvdb::Vec3d direction{0.0, -1.0, 1.0}; ///< towards the light, world, when not a headlight
    double ambient = 0.2;
    double diffuse = 0.8;
    double specular = 0.35;
    double shininess = 16.0;
};

/// The shading of a line of unit tangent `t` seen from unit direction `v` (towards the eye)
/// lit from unit direction `l` (towards the light), for white: see Lighting. Public for tests.
/// Returns {diffuse + ambient part (multiplies colour), specular part (white)}.
std::pair<double, double> lineShade(const Lighting& lighting, const openvdb::Vec3d& t, const openvdb::Vec3d& l,
                                    const openvdb::Vec3d& v);

/// How to turn the volume into light.
///
/// Transfer: density ρ (trilinear) is first windowed, ρ' = clamp((ρ − lo)/(hi − lo), 0, 1);
/// extinction σ = densityScale · ρ' per voxel length (the density grid's smallest voxel edge), so
/// a slab of uniform ρ' and thickness d voxels transmits exp(−densityScale·ρ'·d). Emission is
/// proportional to absorption (a glowing medium of colour c): a step of opacity α adds
/// T·α·brightness·shade(c) to the pixel, T the transmittance so far. Black background.
///
/// Halos (seed §6): the ray is inside a halo where halo > haloThreshold. At each halo exit the
/// accumulated opacity A = 1 − T is raised to min(1, A + haloStrength·max), max the largest halo
/// value inside that halo segment. Only exits raise it, so the segment of the first halo on the
/// ray (the one around the first line hit) is composited normally.
struct RenderSettings
{
    /// Extinction per unit (windowed) density per voxel length (> 0). 0 = auto: 2 for a line bake
    /// (the volume has a `halo` grid), so each line is nearly opaque; otherwise (dense noise
    /// bakes) chosen so that an average ray across the active box has optical depth 2.5:
    /// K = 2.5 / (mean ρ' over the box × mean box edge in voxels), clamped to [0.001, 8].
    /// HaloRaycaster::settings() holds the value used.
    double densityScale = 0.0;
    double densityLow = 0.0;    ///< transfer window: density ≤ lo is transparent
    double densityHigh = 1.0;   ///< transfer window: density ≥ hi has full extinction (> lo)
    double brightness = 1.0;    ///< emission multiplier (≥ 0)
    double step = 0.5;          ///< ray step, voxels (> 0)
    bool halos = true;          ///< use the halo grid if there is one
    double haloStrength = 1.0;  ///< ≥ 0
    double haloThreshold = 0.05;///< in [0, 1)
    std::optional<Colormap> colormap; ///< colour from `scalar` through this map (else `color`, else white)
    Lighting lighting;
    /// Stop a ray once its transmittance falls below this (early ray termination).
    double minTransmittance = 1e-3;
    bool emptySpaceSkipping = true; ///< skip 8³ bricks that cannot contribute (same result)
    int threads = 0;            ///< worker threads, 0 = all cores

    /// @throw lic::InputError naming the first out-of-range value.
    void validate() const;
};

/// Counters of one render (identical for any thread count).
struct RenderStats
{
    std::uint64_t rays = 0;
    std::uint64_t samples = 0;        ///< density/halo samples taken
    std::uint64_t skippedBricks = 0;  ///< brick crossings skipped as empty
};

/// @brief The raycaster: reads the grids where they are (sparse: a table of pointers to their
///        leaves per 8³ block of the active bounding box, plus an 8³-brick occupancy table for
///        empty-space skipping), then renders any number of views of them.
///
/// Rendering is parallel over 32 × 32-pixel tiles (TBB) and deterministic: every pixel is
/// computed independently, so images are bit-identical for any thread count.
class HaloRaycaster
{
public:
    /// @throw lic::InputError if `density` is missing, has no active voxels, or a grid has a
    ///        non-linear transform; if a colormap is set but there is no `scalar` grid; if the
    ///        padded bounding box exceeds 2^31 voxels. lic::Cancelled if `progress` asks.
    HaloRaycaster(const RenderVolume& volume, const RenderSettings& settings,
                  Progress& progress = nullProgress());
    ~HaloRaycaster();
    HaloRaycaster(const HaloRaycaster&) = delete;
    HaloRaycaster& operator=(const HaloRaycaster&) = delete;

    /// World bounding box of the active voxels of `density` (and `halo`): min − ½ … max + ½
    /// voxel through the transform.
    const openvdb::BBoxd& worldBBox() const;
    bool hasHalo() const;    ///< a halo grid was given (halos are used if settings.halos too)
    bool hasColor() const;   ///< colour from `color` or a colormap
    bool hasTangent() const; ///< illumination possible (tangent grid or flow field)
    /// Whether density and halo were copied into dense arrays (their leaves fill at least half of
    /// the box); else every grid is read where it is.
    bool denseCopies() const;
    /// The settings in use (densityScale resolved when it was 0 = auto).
    const RenderSettings& settings() const;

    /// @brief Render one view. @throw lic::Cancelled if `progress` asks.
    Image render(const Camera& camera, Progress& progress = nullProgress(), RenderStats* stats = nullptr) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace lic

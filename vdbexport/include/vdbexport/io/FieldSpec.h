// Which vector field to read and how (a recipe's `field` section, docs/recipe.md): the file or
// frame pattern, its format, and what is done to it on the way in.
#pragma once

#include <array>
#include <optional>
#include <string>

namespace vdbexport {

/// The vector field to convolve (JSON `field`).
struct FieldSpec
{
    std::string path; ///< `path`: field file (VDB, ...); may be empty until the CLI sets it
    std::string grid; ///< `grid`: vector grid name; "" picks the default grid
    /// `format`: "auto" (by extension; a directory with system/controlDict is OpenFOAM) or a name of
    /// the table inputFormats() (InputFormats.h; docs/inputs.md)
    std::string format = "auto";
    /// `voxel_size`: world units per voxel of a dense input (npy, raw; overrides a VTK file's
    /// spacing), > 0; null = the file's own, else 1. For a mesh: the lattice it is resampled
    /// onto; null = the default for LIC (docs/inputs.md: half the 10th percentile of the cell sizes,
    /// within a budget)
    std::optional<double> voxelSize;
    /// `time`: the time of a series (.pvd, OpenFOAM case) to read; null = the latest
    std::optional<double> time;
    /// `solution`: a PLOT3D solution (.q) file; "" = the grid's path with .q
    std::string solution;
    /// `origin`: world position of voxel (0,0,0)'s centre for dense inputs; null = the file's, else 0
    std::optional<std::array<double, 3>> origin;
    /// `shape`: [X, Y, Z] voxels of a raw input (required for raw), each >= 1
    std::optional<std::array<double, 3>> shape;
    /// `dtype`: raw input element type: "float32" | "float64" (little-endian), "<f4", "<f8",
    /// ">f4", ">f8"
    std::string dtype = "float32";
    /// `resample`: resample the field to this voxel size, world units, > 0; null = keep
    std::optional<double> resample;
    /// `crop`: [[x0,y0,z0],[x1,y1,z1]] world-space box; voxels whose centres lie outside are
    /// dropped; null = no crop
    std::optional<std::array<std::array<double, 3>, 2>> crop;
    /// `mask`: "none" | "zero" (deactivate voxels whose velocity is exactly zero)
    std::string mask = "none";
    /// `nan_policy`: "refuse" (NaN/Inf is an error) | "zero" (replace with 0 and go on)
    std::string nanPolicy = "refuse";
    /// `frames`: [first, last] frame numbers of an unsteady sequence; `path` is then a pattern
    /// with a run of `#` (or printf `%04d`, `%d`) for the frame number. null = a single field
    /// (or, with a pattern path, every frame found on disk)
    std::optional<std::array<int, 2>> frames;
    /// `fps`: frames per second of a sequence, > 0: velocity × (1 / fps) is the motion between
    /// frames (world units per second; Blender mantaflow caches are converted, docs/inputs.md)
    double fps = 24;

    bool operator==(const FieldSpec&) const = default;
};

} // namespace vdbexport

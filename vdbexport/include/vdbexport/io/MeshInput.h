// CFD meshes in: VTK XML unstructured (.vtu), structured/curvilinear (.vts), multi-block (.vtm)
// and partitioned collections (.vtpc), time series (.pvd), legacy .vtk unstructured and
// structured grids, PLOT3D (.xyz + .q) and OpenFOAM case directories, read by VTK's own readers
// and resampled by VTK's probe (vtkResampleToImage) onto the VDB lattice. Voxels whose centre
// lies outside every cell stay inactive, so holes, walls and curved boundaries stay empty.
//
// Optional: built when VTK is found (CMake option LICVDB_VTK, Debian libvtk9-dev). Without it
// meshInputAvailable() is false and loadMesh() throws an InputError that says what to install.
#pragma once

#include "vdbexport/io/FieldInput.h"

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport {

/// How to read and resample a mesh.
struct MeshOptions
{
    std::string vectorName;          ///< velocity array; "" = U, velocity, vel, v, else the only vector
    std::optional<double> voxelSize; ///< lattice spacing, world units; null = the default for LIC
    /// Resample inside this world box only (intersected with the mesh's bounds); null = the mesh's
    std::optional<std::array<std::array<double, 3>, 2>> crop;
    std::optional<double> time;      ///< time value of a series (.pvd, OpenFOAM); null = the latest
    std::string solution;            ///< PLOT3D solution (.q) file; "" = the .xyz path with .q
    /// Largest lattice to make (voxels), at most kMaxDenseVoxels
    std::uint64_t maxVoxels = kMaxDenseVoxels;
    /// Called with the fraction done (0..1) of the resampling; return false to cancel (loadMesh
    /// then throws lic::Cancelled).
    std::function<bool(double)> progress;
};

/// True when licvdb was built with VTK (mesh formats available). VTK's readers live in licvdb's
/// mesh module (libexec/licvdb/licvdb-mesh.so), loaded on the first mesh read; a licvdb that
/// cannot find it fails that read with a lic::Error naming where it looked.
bool meshInputAvailable();

/// An environment variable naming the mesh module's file, instead of where licvdb looks for it.
inline constexpr const char* kMeshModuleEnv = "LICVDB_MESH_MODULE";

/// What a mesh file holds, without resampling it (`licvdb convert --list`).
struct MeshSummary
{
    std::string format;
    std::uint64_t cells = 0, points = 0;
    std::size_t blocks = 0;                    ///< non-empty datasets (1 for a single mesh)
    std::array<std::array<double, 3>, 2> bounds{};
    double medianCellSize = 0;                 ///< median over the cells of the cube root of their box's volume
    double defaultVoxelSize = 0;               ///< the lattice's voxel size when none is given
    std::string voxelSizeRule;                 ///< which part of the default's rule chose it
    std::vector<double> times;                 ///< time values of a series; empty for one mesh
    std::optional<double> time;                ///< the time read
    /// Per time of `times`, where it is read from (OpenFOAM: "2 processor directories", "the top
    /// level", …); empty for other formats.
    std::vector<std::string> timeSources;
    /// What the read found suspicious (OpenFOAM: a velocity zero or uniform everywhere, a case with
    /// only its initial conditions); convert writes with these, bake refuses.
    std::vector<std::string> warnings;
    struct Array
    {
        std::string name;
        int components = 1;
        bool cellData = false; ///< on the cells (else on the points)
    };
    std::vector<Array> arrays;
};

/// @brief The time values of a series: a .pvd's timesteps, an OpenFOAM case's times (sorted);
///        empty for a single mesh.
/// @throw lic::InputError for an unreadable file.
std::vector<double> meshTimes(const std::string& path, const std::string& format);

/// @brief Read the mesh at `path` (time options.time) and describe it.
/// @throw lic::InputError naming the file and the problem.
MeshSummary describeMesh(const std::string& path, const std::string& format, const MeshOptions& options);

/// @brief Read the mesh at `path` and resample it onto a lattice of voxel size options.voxelSize
///        (or the default for LIC: docs/inputs.md) whose voxel (0,0,0) sits at the low corner of
///        the bounds: the velocity array becomes a Vec3SGrid, every scalar array a FloatGrid, all
///        active on the voxels inside the mesh and a one-voxel band around them. Cell data reach
///        the lattice by a weighted least-squares linear fit over the nearest cell centres. The grids carry the source in metadata (`source`,
///        `source_format`, `source_array`, `source_time` for series).
/// @throw lic::InputError naming the file and the problem: unreadable or truncated file, no
///        cells, degenerate bounds, no or ambiguous velocity array, an array whose tuple count
///        is not the mesh's, NaN/Inf in the points or (nanPolicy "refuse") the velocity, a time
///        the series lacks, a lattice over kMaxDenseVoxels voxels.
LoadedField loadMesh(const std::string& path, const std::string& format, const MeshOptions& options,
                     const std::string& nanPolicy = "refuse");

} // namespace vdbexport

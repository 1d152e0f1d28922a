// Loading a bake's vector field from any supported file format, and preparing it (NaN policy,
// crop, masking, resampling) before the convolution. One entry point: loadField().
//
// Formats (the table in InputFormats.h): OpenVDB (.vdb: Blender/mantaflow caches, Houdini `vel`
// or split `vel.x/.y/.z`), the dense NumPy (.npy), VTK XML image data (.vti), legacy VTK
// STRUCTURED_POINTS (.vtk) and raw binary (.raw/.bin/.dat with an explicit shape and dtype), and
// meshes (MeshInput.h). Dense formats become sparse Vec3 grids whose voxel (i,j,k) has its centre
// at world position origin + (i,j,k)·voxel_size.
#pragma once

#include "vdbexport/io/FieldSpec.h"
#include "vdbexport/io/InputFormats.h"

#include <lic/util/Progress.h>

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace vdbexport {

/// Largest number of voxels a dense input may declare (2^28 ≈ 268 M voxels, 3.2 GB as Vec3s).
/// Readers refuse larger headers before allocating anything.
inline constexpr std::uint64_t kMaxDenseVoxels = std::uint64_t(1) << 28;

/// A dense regular grid of named arrays, as read from a .npy, .vti, .vtk or raw file.
/// Values are stored x fastest: value of component c at (i,j,k) is
/// `data[((k * dims[1] + j) * dims[0] + i) * components + c]`.
struct DenseImage
{
    struct Array
    {
        std::string name;
        int components = 1; ///< 1 (scalar) or 3 (vector)
        std::vector<float> data;
    };
    std::array<std::int64_t, 3> dims{0, 0, 0}; ///< voxels along x, y, z
    openvdb::Vec3d origin{0.0};                 ///< world position of voxel (0,0,0)'s centre
    openvdb::Vec3d spacing{1.0};                ///< voxel edge lengths, world units
    bool hasGeometry = false;                   ///< origin/spacing came from the file
    std::vector<Array> arrays;

    std::uint64_t voxelCount() const { return std::uint64_t(dims[0]) * std::uint64_t(dims[1]) * std::uint64_t(dims[2]); }
};

/// @brief Parse a NumPy .npy file held in memory: shape (X,Y,Z,3) or (3,X,Y,Z) (a vector field)
///        or (X,Y,Z) (a scalar), dtype float32/float64 of either byte order, C or Fortran order.
/// @param source name of the file, for messages
/// @throw lic::InputError naming `source` and the problem (bad magic, unsupported version,
///        malformed header dict, unsupported dtype or shape, declared size larger than the data
///        or than kMaxDenseVoxels — checked before allocating).
DenseImage parseNpy(std::string_view bytes, const std::string& source);

/// @brief Parse a VTK XML ImageData (.vti) file held in memory: WholeExtent, Origin, Spacing;
///        PointData or CellData DataArrays of Float32/Float64 (and integer types), 1 or 3
///        components, format ascii | binary (base64, UInt32/UInt64 header, optional zlib
///        compression) | appended (raw or base64). One piece.
/// @throw lic::InputError naming `source` and the problem.
DenseImage parseVti(std::string_view bytes, const std::string& source);

/// @brief Parse a legacy VTK file (.vtk) held in memory: DATASET STRUCTURED_POINTS, ASCII or
///        BINARY (big-endian), DIMENSIONS / ORIGIN / SPACING (or ASPECT_RATIO), POINT_DATA or
///        CELL_DATA with VECTORS and SCALARS (float or double).
/// @throw lic::InputError naming `source` and the problem.
DenseImage parseLegacyVtk(std::string_view bytes, const std::string& source);

/// @brief Interpret raw bytes as a (X,Y,Z,3) C-order array (component fastest, then z, y, x —
///        NumPy's default layout) of `dtype` ("float32", "float64", "f4", "<f8", ">f4", …).
/// @throw lic::InputError if the byte count is not X·Y·Z·3·itemsize, the shape has a
///        non-positive or huge dimension, or the dtype is unsupported.
DenseImage parseRaw(std::string_view bytes, const std::array<std::int64_t, 3>& shape,
                    const std::string& dtype, const std::string& source);

/// @brief Turn a dense image into grids: the vector array `vectorName` (empty: `velocity`, `vel`,
///        `v`, else the only 3-component array) becomes a cell-centred Vec3SGrid named
///        `gridName`-or-its-array-name; every 1-component array becomes a FloatGrid. Voxels
///        are all active; values are copied exactly (zeros included, see prepareField's mask).
/// @throw lic::InputError if no suitable vector array exists or the spacing is not positive.
struct LoadedField;
void denseToGrids(const DenseImage& image, const std::string& vectorName, const std::string& source,
                  LoadedField& out);

/// What loadField() returns.
struct LoadedField
{
    openvdb::Vec3SGrid::Ptr velocity;                        ///< the prepared field
    std::map<std::string, openvdb::FloatGrid::Ptr> scalars;  ///< other scalar grids of the file, by name
    std::string gridName;                                    ///< name of the velocity grid or array
    std::string format;                                      ///< the name of its row of inputFormats()
    std::uint64_t nonFiniteReplaced = 0;                     ///< NaN/Inf values set to 0 (nan_policy zero)
    std::vector<std::string> notes;                          ///< what preparation did, for stderr
    /// What reading found suspicious (OpenFOAM: a velocity zero or uniform everywhere, only initial
    /// conditions): `convert` writes the field and prints these, `bake` refuses (exit 2).
    std::vector<std::string> warnings;
};

/// @brief Read the field described by `spec` (format by extension unless `spec.format` is set),
///        apply `voxel_size`/`origin` (dense formats; they override a VTK file's own geometry),
///        then prepareField(). Scalar grids of the same file are returned for colour/ROI/width.
/// @throw lic::InputError naming the file and the problem (see each reader, and prepareField).
LoadedField loadField(const FieldSpec& spec);
/// The same, reporting a mesh's resampling (the long part of a large mesh) to `progress`.
LoadedField loadField(const FieldSpec& spec, lic::Progress& progress);

/// @brief Field preparation, in this order: NaN/Inf policy (refuse: throw with the count and the
///        first voxel and world position; zero: replace with 0), crop to a world-space box,
///        mask (deactivate zero-velocity voxels), resample to a target voxel size. Each step
///        keeps world positions: the transform is carried along.
/// @throw lic::InputError for NaN/Inf under "refuse", a crop box that misses the field, or a
///        field left with no active voxels.
void prepareField(const FieldSpec& spec, const std::string& source, LoadedField& field);

} // namespace vdbexport

// The field formats licvdb reads, as one table: each row a format's name (recipe `field.format`,
// `--format`), the extensions that pick it when the format is "auto", how it is read (a .vdb's
// grids, a dense image parsed in this process, or a mesh through the mesh module) and a phrase
// for messages and help. The recipe's allowed values, `--format`'s help, `licvdb help --json`,
// formatFromPath() and loadField()'s dispatch all read it: a new format is a row here and its reader.
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace vdbexport {

struct DenseImage;
struct FieldSpec;

/// How a format is read.
enum class InputKind
{
    Grid,  ///< OpenVDB grids, read as they are (the only kind a distributed bake reads in parts)
    Dense, ///< a regular lattice parsed in this process by the row's DenseParser (FieldInput.h)
    Mesh,  ///< a CFD mesh read and resampled by VTK in the mesh module (MeshInput.h)
};

/// "grid", "dense" or "mesh" (as `licvdb help --json` lists them).
const char* kindName(InputKind kind);

/// Parses a dense file's whole content into named arrays; `spec` gives what the file does not say
/// (a raw file's shape and dtype). @throw lic::InputError naming `source` and the problem.
using DenseParser = DenseImage (*)(std::string_view bytes, const FieldSpec& spec, const std::string& source);

/// One input format.
struct InputFormat
{
    std::string name;                    ///< "npy": the value of `field.format` / `--format`
    std::vector<std::string> extensions; ///< lower case with the dot, first the usual one: {".raw", ".bin", ".dat"}
    InputKind kind = InputKind::Dense;
    DenseParser parse = nullptr;         ///< Dense rows only
    std::string description;             ///< "a NumPy .npy file": for messages ("expected …") and help
    /// A file without a header (raw): `field.shape` (required) and `field.dtype` say its layout.
    bool needsShape = false;
    /// Paths that are this format whatever their extension (an OpenFOAM case directory); null = none.
    bool (*matchesPath)(const std::string& path) = nullptr;
    /// For a row sharing its extensions with an earlier row (a legacy .vtk mesh beside the dense
    /// .vtk): true when the file's content is this format's. Checked when the earlier row is
    /// chosen, by extension or by name; null = none.
    bool (*matchesContent)(const std::string& path) = nullptr;
};

/// Every input format, in the order help and messages list them.
std::span<const InputFormat> inputFormats();

/// The row named `name`; null for an unknown name (and for "auto").
const InputFormat* findInputFormat(std::string_view name);

/// @brief The format of the field at `path` by the table: a path a row's matchesPath accepts (an
///        OpenFOAM case directory), else the first row listing the extension (case-insensitive).
/// @throw lic::InputError naming the path and its extension, the extensions known and `--format`.
std::string formatFromPath(const std::string& path);

/// @brief The format to read `path` as: `format` unless it is "" or "auto" (then formatFromPath()),
///        replaced by a later row that shares its extensions when that row's matchesContent accepts
///        the file (a legacy VTK mesh in a .vtk file is "vtk-mesh").
/// @throw lic::InputError for an unknown `format` (naming the known ones) or an unknown extension.
std::string resolveInputFormat(const std::string& path, const std::string& format);

/// True for a format read through the mesh module (kind Mesh).
bool isMeshFormat(std::string_view name);

/// The names of the rows of `kind`, in table order: {"npy", "vti", "vtk", "raw"} for Dense.
std::vector<std::string> inputFormatNames(InputKind kind);

/// The values `field.format` accepts: "auto", then every row's name.
std::vector<std::string> inputFormatValues();

/// "auto|vdb|npy|…": inputFormatValues() for a flag's help.
std::string inputFormatHelp();

} // namespace vdbexport

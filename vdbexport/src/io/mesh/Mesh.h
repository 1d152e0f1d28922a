// The mesh module's parts (licvdb-mesh.so, io/MeshModuleApi.h): VTK's messages (Messages.cpp),
// reading each format (Read.cpp; OpenFOAM cases in OpenFoam*.cpp), checking what was read
// (Check.cpp), and resampling it onto the VDB lattice (Resample.cpp). MeshModule.cpp is the
// module's entry table. Internal to the module: nothing here is seen by licvdb itself.
#pragma once

#include "io/MeshModuleApi.h"

#include <vtkAlgorithm.h>
#include <vtkDataObject.h>
#include <vtkDataSet.h>
#include <vtkSmartPointer.h>

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport::mesh_module {

// ---- messages (Messages.cpp) ----------------------------------------------------------------

/// A number as a user writes it: up to 6 significant digits, no trailing zeros.
std::string num(double v);
/// VTK reports problems (a truncated file, a bad tag) on its output window, not by exceptions;
/// the module's window keeps them. Forget what it kept.
void clearVtkErrors();
/// The error text VTK reported since clearVtkErrors().
std::string vtkErrors();
/// The first error of VTK's error text, without its "ERROR: In file, line N / vtkClass (0x...): " prefix.
std::string firstError(const std::string& text);
/// Run `update` on `algorithm` and throw the first error VTK reported for it.
void runChecked(vtkAlgorithm* algorithm, const std::string& path, const std::string& what,
                const std::function<void()>& update);

// ---- reading (Read.cpp, OpenFoam*.cpp) --------------------------------------------------------

/// `s` in lower case (ASCII).
std::string lower(std::string s);
/// "a VTK XML unstructured grid (.vtu)" for "vtu", and so on: for messages.
std::string describeFormat(const std::string& format);
/// `path` is an existing, non-empty regular file, else an InputError expecting `what`.
void requireFile(const std::string& path, const std::string& what);
std::vector<double> sortedUnique(std::vector<double> t);
/// The time to read among `times` (sorted): `wanted` (which must be one of them, to 1e-9
/// relative) or the latest.
double chooseTime(const std::vector<double>& times, const std::optional<double>& wanted, const std::string& path);
/// What a read found worth telling beside the data (OpenFOAM: where the time came from, files left
/// out, a velocity that is zero or uniform everywhere): notes for stderr, warnings (convert writes
/// with them, bake refuses), and where each time of the series is read from. The reads add to it;
/// the module's table hands it on in its MeshSummary or LoadedField (MeshModule.cpp, Resample.cpp).
struct ReadReport
{
    std::vector<std::string> notes, warnings;
    std::vector<std::string> timeSources; ///< one per time of the series (OpenFOAM); empty otherwise
    /// Set by the caller: the read only describes (`convert --list`), so what would refuse a load
    /// (OpenFOAM: a time without a velocity file) is a warning instead.
    bool describing = false;
};
/// What the reader of `format` gives for `path`: the time read and the series' times (sorted) are
/// set for a series (pvd, openfoam), left empty otherwise; what it found is added to `report`.
vtkSmartPointer<vtkDataObject> readSingle(const std::string& path, const std::string& format, const MeshOptions& options,
                                          std::optional<double>& timeRead, std::vector<double>& times,
                                          ReadReport& report);
/// An OpenFOAM case's times (sorted): those of the top level and of the processor*/ directories
/// (OpenFoamTimes.cpp).
std::vector<double> openFoamTimes(const std::string& path);
/// An OpenFOAM case's internal mesh and fields at options.time (or the latest time), read through a
/// shadow case (OpenFoamCase.cpp): from the processor directories when all have the time, else from the
/// top level; adds to `report` the times' sources, the source read, files left out or expanded, and
/// zero/uniform velocity.
vtkSmartPointer<vtkDataObject> readOpenFoam(const std::string& path, const MeshOptions& options,
                                            std::optional<double>& timeRead, std::vector<double>& times,
                                            ReadReport& report);

// ---- checking (Check.cpp) ---------------------------------------------------------------------

/// A read mesh, checked.
struct Mesh
{
    vtkSmartPointer<vtkDataObject> data;
    std::vector<vtkSmartPointer<vtkDataSet>> leaves;
    std::optional<double> time;
    std::vector<double> times;
    ReadReport report; ///< what the read found (its notes and warnings go to the caller's summary or field)
};

/// Read `path` and check it: cells, points and arrays that VTK's filters can use safely.
/// `describing`: the read only describes (ReadReport::describing).
Mesh readMesh(const std::string& path, const std::string& format, const MeshOptions& options, bool describing = false);
/// The non-empty datasets of what a reader gave (a dataset, or the leaves of a composite).
std::vector<vtkSmartPointer<vtkDataSet>> leavesOf(vtkDataObject* data);
/// VTK's own arrays (vtkValidPointMask, vtkGhostType...), not the file's.
bool internalArray(const char* name);
/// The velocity array's name: `wanted`, or U / velocity / vel / v (any case), or the only
/// 3-component array. It must be in every block.
std::string chooseVelocity(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& wanted,
                           const std::string& path);
/// NaN/Inf in the velocity: refused with the first offender, or set to zero (returns how many).
std::uint64_t checkVelocityValues(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& name,
                                  const std::string& nanPolicy, const std::string& path);
/// The cube root of each cell's bounding-box volume (its largest edge for a flat cell), over a
/// sample of at most ~200 000 cells, sorted.
std::vector<double> cellSizes(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves);
/// The median over (a sample of) the cells of the cube root of each cell's bounding-box volume.
double medianCellSize(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves);
/// The lattice's voxel size when none is given (the default for LIC, docs/inputs.md), and in
/// `rule` which part of the rule chose it (Resample.cpp).
double defaultLatticeVoxelSize(const Mesh& m, const MeshOptions& options, const std::string& path, std::string& rule);
std::array<std::array<double, 3>, 2> boundsOf(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves);

} // namespace vdbexport::mesh_module

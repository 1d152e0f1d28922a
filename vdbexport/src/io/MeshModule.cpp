// CFD meshes through VTK, built as licvdb's mesh module, licvdb-mesh.so (MeshModuleApi.h), which
// licvdb loads on first use; the functions of MeshInput.h (MeshInput.cpp) read the mesh in a child
// process first, then call these. VTK's readers parse the files (mesh/Read.cpp, mesh/OpenFoam*.cpp),
// mesh/Check.cpp checks what they gave, and mesh/Resample.cpp samples it on the VDB lattice
// (VTK's probe) and turns the samples inside the mesh into grids. This file is the module's table.
#include "io/mesh/Mesh.h"

#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <set>

namespace vdbexport::mesh_module {

MeshSummary describeMesh(const std::string& path, const std::string& format, const MeshOptions& options)
{
    const Mesh m = readMesh(path, format, options, /*describing=*/true); // a case without a velocity is described
    MeshSummary s;
    s.timeSources = m.report.timeSources;
    s.warnings = m.report.warnings;
    s.format = format;
    s.blocks = m.leaves.size();
    for (const auto& ds : m.leaves) {
        s.cells += std::uint64_t(ds->GetNumberOfCells());
        s.points += std::uint64_t(ds->GetNumberOfPoints());
    }
    s.bounds = boundsOf(m.leaves);
    s.medianCellSize = medianCellSize(m.leaves);
    s.defaultVoxelSize = defaultLatticeVoxelSize(m, options, path, s.voxelSizeRule);
    s.times = m.times;
    s.time = m.time;
    std::set<std::pair<std::string, bool>> seen;
    for (const auto& ds : m.leaves)
        for (int onCells = 0; onCells < 2; ++onCells) {
            vtkDataSetAttributes* attrs = onCells ? static_cast<vtkDataSetAttributes*>(ds->GetCellData()) : ds->GetPointData();
            for (int a = 0; a < attrs->GetNumberOfArrays(); ++a)
                if (vtkDataArray* arr = attrs->GetArray(a); arr && !internalArray(arr->GetName())
                                                            && seen.insert({arr->GetName(), onCells == 1}).second)
                    s.arrays.push_back({arr->GetName(), arr->GetNumberOfComponents(), onCells == 1});
        }
    return s;
}

namespace {

// The module's table: the functions above, their exceptions reported as a Status.
constexpr const char* kWhere = "the mesh module";

Status timesEntry(const std::string& path, const std::string& format, std::vector<double>& times)
{
    return module::guarded([&] { times = mesh_module::meshTimes(path, format); }, kWhere);
}

Status describeEntry(const std::string& path, const std::string& format, const MeshOptions& options,
                     MeshSummary& summary)
{
    return module::guarded([&] { summary = mesh_module::describeMesh(path, format, options); }, kWhere);
}

Status loadEntry(const std::string& path, const std::string& format, const MeshOptions& options,
                 const std::string& nanPolicy, LoadedField& field)
{
    return module::guarded([&] { field = mesh_module::loadMesh(path, format, options, nanPolicy); }, kWhere);
}

std::string describeFormatEntry(const std::string& format) { return describeFormat(format); }

const Api kApi{kModule.version, timesEntry, describeEntry, loadEntry, describeFormatEntry};

} // namespace

} // namespace vdbexport::mesh_module

extern "C" __attribute__((visibility("default"))) const vdbexport::mesh_module::Api* licvdb_mesh_module()
{
    return &vdbexport::mesh_module::kApi;
}

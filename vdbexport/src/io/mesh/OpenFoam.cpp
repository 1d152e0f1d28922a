// OpenFOAM cases through VTK's reader: the internal mesh and its fields at one time.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <vtkDoubleArray.h>
#include <vtkOpenFOAMReader.h>

#include <filesystem>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace {

/// The OpenFOAM reader's file: <case>/system/controlDict for a case directory, else the file given
/// (a ParaView-style empty `case.foam`, or controlDict itself).
std::string openFoamFile(const std::string& path)
{
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
        const fs::path dict = fs::path(path) / "system" / "controlDict";
        if (!fs::exists(dict, ec))
            throw lic::InputError(q(path) + " is a directory but not an OpenFOAM case: it has no system/controlDict");
        return dict.string();
    }
    if (!fs::exists(path, ec)) throw lic::InputError("OpenFOAM case " + q(path) + " not found");
    const fs::path dir = fs::path(path).filename() == "controlDict" ? fs::path(path).parent_path().parent_path()
                                                                      : fs::path(path).parent_path();
    if (!fs::exists(dir / "system" / "controlDict", ec))
        throw lic::InputError(q(path) + ": the OpenFOAM case " + q(dir.string()) + " has no system/controlDict");
    return path;
}

vtkSmartPointer<vtkOpenFOAMReader> openFoamReader(const std::string& path)
{
    auto r = vtkSmartPointer<vtkOpenFOAMReader>::New();
    r->SetFileName(openFoamFile(path).c_str());
    r->SkipZeroTimeOff(); // a case with only its 0/ directory is still a field
    r->CreateCellToPointOn();
    r->DecomposePolyhedraOn();
    r->ReadZonesOff();
    runChecked(r, path, describeFormat("openfoam"), [&] { r->UpdateInformation(); });
    r->EnableAllCellArrays();
    r->EnableAllPointArrays();
    for (int i = 0; i < r->GetNumberOfPatchArrays(); ++i) {
        const std::string name = r->GetPatchArrayName(i);
        r->SetPatchArrayStatus(name.c_str(), name == "internalMesh" ? 1 : 0);
    }
    return r;
}

} // namespace

std::vector<double> openFoamTimes(const std::string& path)
{
    auto r = openFoamReader(path);
    std::vector<double> t;
    vtkDoubleArray* tv = r->GetTimeValues();
    for (vtkIdType i = 0; tv && i < tv->GetNumberOfTuples(); ++i) t.push_back(tv->GetValue(i));
    return sortedUnique(t);
}

vtkSmartPointer<vtkDataObject> readOpenFoam(const std::string& path, const MeshOptions& options,
                                            std::optional<double>& timeRead, std::vector<double>& times)
{
    auto r = openFoamReader(path);
    vtkDoubleArray* tv = r->GetTimeValues();
    for (vtkIdType i = 0; tv && i < tv->GetNumberOfTuples(); ++i) times.push_back(tv->GetValue(i));
    times = sortedUnique(times);
    if (times.empty()) detail::inputError(path, "is an OpenFOAM case without time directories (no 0/ or later)");
    const double t = chooseTime(times, options.time, path);
    timeRead = t;
    runChecked(r, path, describeFormat("openfoam"), [&] { r->UpdateTimeStep(t); });
    return r->GetOutputDataObject(0);
}

} // namespace vdbexport::mesh_module

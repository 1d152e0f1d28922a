// OpenFOAM cases through VTK's readers: the internal mesh and its fields at one time, read from
// the case's shadow (OpenFoamCase.cpp) by vtkOpenFOAMReader, or, for a time the processor
// directories have (OpenFoamTimes.cpp), by vtkPOpenFOAMReader (all processor directories in this
// process through a vtkDummyController), its processors' meshes then merged into one. The read's
// report says where the time came from, files left out or expanded, and a velocity that is zero or
// uniform everywhere.
#include "io/mesh/Mesh.h"
#include "io/mesh/OpenFoamImpl.h"

#include "io/DenseCommon.h"
#include "io/mesh/FoamDict.h"

#include <lic/util/Error.h>

#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkDataArray.h>
#include <vtkDummyController.h>
#include <vtkIdList.h>
#include <vtkInformation.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkNew.h>
#include <vtkOpenFOAMReader.h>
#include <vtkPOpenFOAMReader.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkUnstructuredGrid.h>

#include <algorithm>
#include <cmath>
#include <unordered_map>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;
using namespace openfoam;

namespace {

vtkSmartPointer<vtkOpenFOAMReader> makeReader(const fs::path& controlDict, bool decomposed, const std::string& path,
                                              const fs::path& shadow, const fs::path& caseDir)
{
    vtkSmartPointer<vtkOpenFOAMReader> r;
    if (decomposed) {
        // One process reads every processor directory: vtkPOpenFOAMReader gives processor
        // directories to ranks ProcessId, ProcessId + NumProcesses, …, and needs a controller
        // (a null one crashes in RequestData).
        auto p = vtkSmartPointer<vtkPOpenFOAMReader>::New();
        auto controller = vtkSmartPointer<vtkDummyController>::New();
        p->SetController(controller);
        p->SetCaseType(vtkPOpenFOAMReader::DECOMPOSED_CASE);
        r = p;
    } else {
        r = vtkSmartPointer<vtkOpenFOAMReader>::New();
    }
    r->SetFileName(controlDict.string().c_str());
    r->SkipZeroTimeOff(); // a case with only its 0/ directory is still a field
    r->CreateCellToPointOn();
    r->DecomposePolyhedraOn();
    r->ReadZonesOff();
    try {
        runChecked(r, path, describeFormat("openfoam"), [&] { r->UpdateInformation(); });
    } catch (const lic::InputError& e) {
        throw lic::InputError(unshadow(e.what(), shadow, caseDir));
    }
    r->EnableAllCellArrays();
    r->EnableAllPointArrays();
    for (int i = 0; i < r->GetNumberOfPatchArrays(); ++i) {
        const std::string name = r->GetPatchArrayName(i);
        r->SetPatchArrayStatus(name.c_str(), name == "internalMesh" ? 1 : 0);
    }
    return r;
}

/// The processors' internal meshes as one mesh whose points on the processor interfaces are merged
/// (vtkPOpenFOAMReader appends them with each processor's copy of those points): the interfaces
/// are then inside the mesh, as in the reconstructed case, not a boundary of it. Exactly coincident
/// points only (processors write the same numbers); a merged point keeps the first processor's
/// point values, which VTK computes equal on both sides of a plain processor interface.
vtkSmartPointer<vtkDataObject> mergedProcessors(vtkDataObject* data)
{
    const auto leaves = leavesOf(data);
    if (leaves.size() != 1) return data;
    auto* in = vtkUnstructuredGrid::SafeDownCast(leaves.front());
    if (!in || !in->GetPoints()) return data;
    struct Key
    {
        double x, y, z;
        bool operator==(const Key& o) const { return x == o.x && y == o.y && z == o.z; }
    };
    struct KeyHash
    {
        std::size_t operator()(const Key& k) const noexcept
        {
            return std::hash<double>()(k.x) ^ (std::hash<double>()(k.y) * 31) ^ (std::hash<double>()(k.z) * 1031);
        }
    };
    const vtkIdType n = in->GetNumberOfPoints();
    std::unordered_map<Key, vtkIdType, KeyHash> seen;
    seen.reserve(std::size_t(n));
    std::vector<vtkIdType> map(static_cast<std::size_t>(n));
    auto points = vtkSmartPointer<vtkPoints>::New();
    points->SetDataType(in->GetPoints()->GetDataType());
    auto out = vtkSmartPointer<vtkUnstructuredGrid>::New();
    out->GetPointData()->CopyAllocate(in->GetPointData(), n);
    double p[3];
    for (vtkIdType i = 0; i < n; ++i) {
        in->GetPoint(i, p);
        const auto [it, fresh] = seen.try_emplace(Key{p[0], p[1], p[2]}, points->GetNumberOfPoints());
        if (fresh) {
            points->InsertNextPoint(p);
            out->GetPointData()->CopyData(in->GetPointData(), i, it->second);
        }
        map[std::size_t(i)] = it->second;
    }
    if (points->GetNumberOfPoints() == n) return data; // nothing shared
    out->SetPoints(points);
    out->Allocate(in->GetNumberOfCells());
    vtkNew<vtkIdList> ids, faces;
    for (vtkIdType c = 0; c < in->GetNumberOfCells(); ++c) {
        const int type = in->GetCellType(c);
        if (type == VTK_POLYHEDRON) { // face stream: nFaces, (nPts, ids…)…
            in->GetFaceStream(c, faces);
            vtkIdType k = 0;
            const vtkIdType nFaces = faces->GetId(k++);
            for (vtkIdType f = 0; f < nFaces; ++f) {
                const vtkIdType m = faces->GetId(k++);
                for (vtkIdType j = 0; j < m; ++j, ++k) faces->SetId(k, map[std::size_t(faces->GetId(k))]);
            }
            in->GetCellPoints(c, ids);
            for (vtkIdType j = 0; j < ids->GetNumberOfIds(); ++j) ids->SetId(j, map[std::size_t(ids->GetId(j))]);
            out->InsertNextCell(type, ids->GetNumberOfIds(), ids->GetPointer(0), nFaces, faces->GetPointer(1));
            continue;
        }
        in->GetCellPoints(c, ids);
        for (vtkIdType j = 0; j < ids->GetNumberOfIds(); ++j) ids->SetId(j, map[std::size_t(ids->GetId(j))]);
        out->InsertNextCell(type, ids);
    }
    out->GetCellData()->ShallowCopy(in->GetCellData());
    auto blocks = vtkSmartPointer<vtkMultiBlockDataSet>::New();
    blocks->SetBlock(0, out);
    blocks->GetMetaData(0u)->Set(vtkCompositeDataSet::NAME(), "internalMesh");
    return blocks;
}

std::string vecText(const double* v) { return "(" + num(v[0]) + " " + num(v[1]) + " " + num(v[2]) + ")"; }

/// A warning in `report` when the velocity read is zero or the same vector everywhere.
void checkNotUniform(vtkDataObject* data, const MeshOptions& options, const std::string& path, double t,
                     ReadReport& report)
{
    const auto leaves = leavesOf(data);
    if (leaves.empty()) return;
    std::string name;
    try {
        name = chooseVelocity(leaves, options.vectorName, path);
    } catch (const lic::Error&) {
        return; // no velocity: said where it matters (loadMesh)
    }
    double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    vtkIdType n = 0;
    for (const auto& ds : leaves) {
        vtkDataArray* a = ds->GetCellData()->GetArray(name.c_str());
        if (!a) a = ds->GetPointData()->GetArray(name.c_str());
        if (!a || a->GetNumberOfComponents() != 3) return;
        for (vtkIdType i = 0; i < a->GetNumberOfTuples(); ++i, ++n)
            for (int c = 0; c < 3; ++c) {
                const double v = a->GetComponent(i, c);
                lo[c] = std::min(lo[c], v);
                hi[c] = std::max(hi[c], v);
            }
    }
    if (n == 0) return;
    double scale = 0, spread = 0;
    for (int c = 0; c < 3; ++c) {
        scale = std::max({scale, std::abs(lo[c]), std::abs(hi[c])});
        spread = std::max(spread, hi[c] - lo[c]);
    }
    if (!(spread <= 1e-9 * scale)) return;
    const std::string at = "at time " + num(t);
    if (scale == 0)
        report.warnings.push_back("the velocity " + name + " is zero everywhere " + at
                                  + " (an initial condition, not a solution?): the field has no flow to draw");
    else
        report.warnings.push_back("the velocity " + name + " is uniform " + at + ", " + vecText(lo)
                                  + " in every cell (an initial condition, not a solution?): its lines are straight "
                                    "and parallel");
}

} // namespace

vtkSmartPointer<vtkDataObject> readOpenFoam(const std::string& path, const MeshOptions& options,
                                            std::optional<double>& timeRead, std::vector<double>& times,
                                            ReadReport& report)
{
    const FoamCase c = scanCase(path);
    if (c.times.empty())
        detail::inputError(path, "is an OpenFOAM case without time directories (no 0/ or later"
                                 + std::string(c.processors.empty() ? "" : ", at the top level or in processor*/")
                                 + "): nothing to read");
    times.clear();
    for (const auto& ft : c.times) times.push_back(ft.value);
    report.timeSources.clear();
    for (const auto& ft : c.times) report.timeSources.push_back(sourceText(c, ft));
    const double t = chooseTime(times, options.time, path);
    const FoamTime& ft = *std::find_if(c.times.begin(), c.times.end(), [&](const FoamTime& x) { return x.value == t; });
    timeRead = t;
    if (ft.from == From::Incomplete) {
        std::vector<std::string> complete;
        for (const auto& x : c.times)
            if (x.from != From::Incomplete) complete.push_back(num(x.value));
        detail::inputError(path, "time " + num(t) + " is only in " + joinedList(processorsWith(c, ft, true)) + ", not in "
                                 + joinedList(processorsWith(c, ft, false)) + " nor at the top level (a run cut short, "
                                 "or still writing?): pick a complete time with --time"
                                 + (complete.empty() ? std::string(" (there is none)") : " (" + joinedList(complete) + ")"));
    }
    const bool decomposed = ft.from == From::Processors;

    // The mesh of each root read.
    std::vector<fs::path> roots;
    std::vector<std::string> labels, timeNames;
    if (decomposed) {
        for (std::size_t i = 0; i < c.processors.size(); ++i) {
            roots.push_back(c.dir / c.processors[i]);
            labels.push_back(c.processors[i]);
            timeNames.push_back(ft.procNames[i]);
        }
    } else {
        roots.push_back(c.dir);
        labels.emplace_back();
        timeNames.push_back(*ft.topName);
    }
    std::vector<std::string> meshDirs;
    for (std::size_t i = 0; i < roots.size(); ++i) {
        const auto m = meshInstance(roots[i], t);
        if (!m) {
            if (decomposed)
                detail::inputError(path, "has no mesh in " + labels[i] + "/: " + labels[i] + "/constant/polyMesh is missing "
                                         "(decomposePar writes it from the case's constant/polyMesh; make that with "
                                         "blockMesh, or snappyHexMesh, first, then run decomposePar)");
            detail::inputError(path, "has no mesh: constant/polyMesh is missing (make it with blockMesh, or "
                                     "snappyHexMesh, in the case directory"
                                     + std::string(c.processors.empty() ? ""
                                                                        : "; the processor directories do not have time "
                                                                              + num(t) + " to read it from them")
                                     + ")");
        }
        meshDirs.push_back(*m);
    }

    // The shadow case: the time read, its field files as VTK should see them.
    ShadowDir shadow;
    const std::vector<fs::path> etcDirs = foamEtcDirs();
    std::vector<TimeFields> fields(roots.size());
    for (std::size_t i = 0; i < roots.size(); ++i) {
        const fs::path dst = decomposed ? shadow.path() / labels[i] : shadow.path();
        shadowRoot(roots[i], dst, labels[i], timeNames[i], meshDirs[i], options.vectorName, etcDirs, fields[i]);
    }
    if (decomposed) { // the top level's system/ (controlDict) and constant/ (if any)
        std::error_code ec;
        for (const char* d : {"system", "constant"})
            if (fs::is_directory(c.dir / d, ec))
                fs::create_directory_symlink(fs::absolute(c.dir / d), shadow.path() / d);
    }

    // A time without a velocity file is said so here, not as "no velocity array".
    const std::string source = decomposed ? processorsText(c) : "the top level";
    const std::string where = "time " + num(t) + " (read from " + source + ")";
    bool saidNoVelocity = false;
    auto noVelocity = [&](const std::string& what) { // an error, but for a description (--list)
        if (!report.describing) detail::inputError(path, what);
        if (!saidNoVelocity) report.warnings.push_back(what);
        saidNoVelocity = true;
    };
    for (std::size_t i = 0; i < roots.size(); ++i) {
        const TimeFields& f = fields[i];
        const std::string dir = (labels[i].empty() ? "" : labels[i] + "/") + timeNames[i] + "/";
        const std::string has = f.fields.empty() ? "no fields" : "fields " + joinedList(f.fields);
        if (!options.vectorName.empty()) {
            if (std::find(f.fields.begin(), f.fields.end(), options.vectorName) == f.fields.end())
                noVelocity(where + " has no field file " + q(options.vectorName) + ": " + dir + " holds " + has);
        } else if (std::find(f.fields.begin(), f.fields.end(), "U") == f.fields.end() && f.vectors.empty()) {
            std::vector<std::string> withU;
            for (const auto& x : c.times) {
                const fs::path d = x.from == From::Processors ? c.dir / c.processors.front() / x.procNames.front()
                                   : x.topName                ? c.dir / *x.topName
                                                              : fs::path();
                std::error_code ec;
                if (!d.empty() && (fs::exists(d / "U", ec) || fs::exists(d / "U.gz", ec))) withU.push_back(num(x.value));
            }
            noVelocity(where + " has no velocity: " + dir + " holds " + has + ", no U (nor any vector field)"
                       + (withU.empty() ? std::string("; no time of the case has U") : "; times with U: " + joinedList(withU)));
        }
    }

    const fs::path controlDict = shadow.path() / "system" / "controlDict";
    auto r = makeReader(controlDict, decomposed, path, shadow.path(), c.dir);
    try {
        runChecked(r, path, describeFormat("openfoam"), [&] { r->UpdateTimeStep(t); });
    } catch (const lic::InputError& e) {
        throw lic::InputError(unshadow(e.what(), shadow.path(), c.dir));
    }
    vtkSmartPointer<vtkDataObject> data = r->GetOutputDataObject(0);
    if (decomposed) data = mergedProcessors(data);

    // What the read was.
    std::string readNote = "read time " + num(t) + " of the OpenFOAM case from ";
    if (decomposed) {
        readNote += processorsText(c) + " (" + joinedList(c.processors) + ")";
    } else {
        readNote += "the top level";
        if (!c.processors.empty()) {
            const auto with = processorsWith(c, ft, true);
            readNote += with.empty() ? " (the processor directories do not have it)"
                                     : " (only " + joinedList(with) + " of " + processorsText(c) + " have it)";
        }
    }
    report.notes.push_back(readNote);
    std::vector<std::string> leftOut, expanded;
    for (const auto& f : fields) {
        leftOut.insert(leftOut.end(), f.leftOut.begin(), f.leftOut.end());
        expanded.insert(expanded.end(), f.expanded.begin(), f.expanded.end());
    }
    if (!leftOut.empty())
        report.notes.push_back("left out " + joinedList(leftOut)
                               + ": backups, or files whose header names another field (the field named U is the "
                                 "file U; --grid FILE reads one by its file name)");
    if (!expanded.empty()) report.notes.push_back("expanded the dictionary directives of " + joinedList(expanded));
    if (times.size() == 1 && times.front() == 0)
        report.warnings.push_back("the case has only its initial conditions (0/"
                                  + std::string(decomposed ? " in the processor directories" : "")
                                  + "): no solver has written a time yet; run the solver first (e.g. `simpleFoam`, or "
                                    "`mpirun -np N <solver> -parallel` for a decomposed case)");
    checkNotUniform(data, options, path, t, report);
    return data;
}

} // namespace vdbexport::mesh_module

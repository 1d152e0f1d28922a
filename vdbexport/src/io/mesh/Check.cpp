// Checking what a VTK reader gave before any VTK filter touches it: array sizes, points, cells
// (types, point counts, polyhedron faces), the velocity array and its values; the mesh's size.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkCellTypes.h>
#include <vtkCompositeDataIterator.h>
#include <vtkCompositeDataSet.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkIdTypeArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkStructuredGrid.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnstructuredGrid.h>

#include <algorithm>
#include <cmath>
#include <set>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

std::vector<vtkSmartPointer<vtkDataSet>> leavesOf(vtkDataObject* data)
{
    std::vector<vtkSmartPointer<vtkDataSet>> leaves;
    if (auto* ds = vtkDataSet::SafeDownCast(data)) {
        if (ds->GetNumberOfCells() > 0) leaves.emplace_back(ds);
    } else if (auto* cds = vtkCompositeDataSet::SafeDownCast(data)) {
        vtkSmartPointer<vtkCompositeDataIterator> it;
        it.TakeReference(cds->NewIterator());
        for (it->InitTraversal(); !it->IsDoneWithTraversal(); it->GoToNextItem())
            if (auto* leaf = vtkDataSet::SafeDownCast(it->GetCurrentDataObject()))
                if (leaf->GetNumberOfCells() > 0) leaves.emplace_back(leaf);
    }
    return leaves;
}

bool internalArray(const char* name) { return !name || std::string(name).rfind("vtk", 0) == 0; }

namespace {

/// Every array's tuple count is the number of points (point data) or cells (cell data).
void checkTupleCounts(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& path)
{
    for (std::size_t b = 0; b < leaves.size(); ++b) {
        vtkDataSet* ds = leaves[b];
        for (int onCells = 0; onCells < 2; ++onCells) {
            vtkDataSetAttributes* attrs = onCells ? static_cast<vtkDataSetAttributes*>(ds->GetCellData()) : ds->GetPointData();
            const vtkIdType want = onCells ? ds->GetNumberOfCells() : ds->GetNumberOfPoints();
            for (int a = 0; a < attrs->GetNumberOfArrays(); ++a) {
                vtkAbstractArray* arr = attrs->GetAbstractArray(a);
                if (!arr || arr->GetNumberOfTuples() == want) continue;
                detail::inputError(path, std::string(onCells ? "cell" : "point") + " array " + q(arr->GetName() ? arr->GetName() : "?")
                                         + (leaves.size() > 1 ? " of block " + std::to_string(b) : "") + " has "
                                         + std::to_string(arr->GetNumberOfTuples()) + " tuples; the mesh has "
                                         + std::to_string(want) + (onCells ? " cells" : " points"));
            }
        }
    }
}

void checkPoints(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& path)
{
    double p[3];
    for (const auto& ds : leaves)
        for (vtkIdType i = 0; i < ds->GetNumberOfPoints(); ++i) {
            ds->GetPoint(i, p);
            if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
                detail::inputError(path, "point " + std::to_string(i) + " of the mesh has a NaN/Inf coordinate");
        }
}

/// Points a cell of VTK type `type` must have: the count for fixed-size types, kVariable for the
/// variable-size types licvdb accepts, nothing for types it refuses (higher-order Lagrange/Bezier
/// cells, unknown numbers). VTK's filters index points by these counts without checking them.
constexpr int kVariable = -1;
std::optional<int> pointsOfCellType(int type)
{
    switch (type) {
    case VTK_EMPTY_CELL: return 0;
    case VTK_VERTEX: return 1;
    case VTK_LINE: return 2;
    case VTK_TRIANGLE: return 3;
    case VTK_PIXEL:
    case VTK_QUAD:
    case VTK_TETRA: return 4;
    case VTK_VOXEL:
    case VTK_HEXAHEDRON: return 8;
    case VTK_WEDGE: return 6;
    case VTK_PYRAMID: return 5;
    case VTK_PENTAGONAL_PRISM: return 10;
    case VTK_HEXAGONAL_PRISM: return 12;
    case VTK_QUADRATIC_EDGE: return 3;
    case VTK_QUADRATIC_TRIANGLE: return 6;
    case VTK_QUADRATIC_QUAD: return 8;
    case VTK_QUADRATIC_TETRA: return 10;
    case VTK_QUADRATIC_HEXAHEDRON: return 20;
    case VTK_QUADRATIC_WEDGE: return 15;
    case VTK_QUADRATIC_PYRAMID: return 13;
    case VTK_BIQUADRATIC_QUAD: return 9;
    case VTK_TRIQUADRATIC_HEXAHEDRON: return 27;
    case VTK_QUADRATIC_LINEAR_QUAD: return 6;
    case VTK_QUADRATIC_LINEAR_WEDGE: return 12;
    case VTK_BIQUADRATIC_QUADRATIC_WEDGE: return 18;
    case VTK_BIQUADRATIC_QUADRATIC_HEXAHEDRON: return 24;
    case VTK_BIQUADRATIC_TRIANGLE: return 7;
    case VTK_CUBIC_LINE: return 4;
    case VTK_TRIQUADRATIC_PYRAMID: return 19;
    case VTK_POLY_VERTEX:
    case VTK_POLY_LINE:
    case VTK_TRIANGLE_STRIP:
    case VTK_POLYGON:
    case VTK_QUADRATIC_POLYGON:
    case VTK_CONVEX_POINT_SET:
    case VTK_POLYHEDRON: return kVariable;
    default: return std::nullopt;
    }
}

/// A polyhedron's face stream (vtkUnstructuredGrid::GetFaces at its location): in the array, each
/// face's points among the cell's own points. VTK's polyhedron follows the stream unchecked.
void checkPolyhedronFaces(vtkUnstructuredGrid* ug, vtkIdType c, const std::set<vtkIdType>& cellPoints,
                          const std::string& block, const std::string& path)
{
    const auto where = [&] { return "cell " + std::to_string(c) + block; };
    vtkIdTypeArray* faces = ug->GetFaces();
    vtkIdTypeArray* locations = ug->GetFaceLocations();
    if (!faces || !locations || c >= locations->GetNumberOfTuples())
        detail::inputError(path, where() + " is a polyhedron without faces");
    const vtkIdType n = faces->GetNumberOfTuples();
    vtkIdType at = locations->GetValue(c);
    auto next = [&]() -> vtkIdType {
        if (at < 0 || at >= n) detail::inputError(path, where() + " (a polyhedron) has a face list that runs past the faces array");
        return faces->GetValue(at++);
    };
    const vtkIdType nFaces = next();
    if (nFaces < 4 || nFaces > n) detail::inputError(path, where() + " (a polyhedron) has " + std::to_string(nFaces) + " faces");
    for (vtkIdType f = 0; f < nFaces; ++f) {
        const vtkIdType nPts = next();
        if (nPts < 3 || nPts > n) detail::inputError(path, where() + " (a polyhedron) has a face of " + std::to_string(nPts) + " points");
        for (vtkIdType k = 0; k < nPts; ++k)
            if (!cellPoints.count(next()))
                detail::inputError(path, where() + " (a polyhedron) has a face point that is not one of the cell's points");
    }
}

/// The cells refer to points that exist, in the numbers their types need, and their arrays agree
/// (VTK's readers accept a connectivity index past the points, a hexahedron of three points or an
/// unknown type code, and its filters then read out of bounds).
void checkCells(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& path)
{
    for (std::size_t b = 0; b < leaves.size(); ++b) {
        const std::string block = leaves.size() > 1 ? " of block " + std::to_string(b) : "";
        if (auto* sg = vtkStructuredGrid::SafeDownCast(leaves[b])) {
            int d[3];
            sg->GetDimensions(d);
            if (vtkIdType(d[0]) * d[1] * d[2] != sg->GetNumberOfPoints())
                detail::inputError(path, "structured grid" + block + " has dimensions " + std::to_string(d[0]) + "x"
                                         + std::to_string(d[1]) + "x" + std::to_string(d[2]) + " but "
                                         + std::to_string(sg->GetNumberOfPoints()) + " points");
            continue;
        }
        auto* ug = vtkUnstructuredGrid::SafeDownCast(leaves[b]);
        if (!ug) continue; // image and rectilinear data: implicit cells
        vtkCellArray* cells = ug->GetCells();
        vtkUnsignedCharArray* types = ug->GetCellTypesArray();
        const vtkIdType nCells = ug->GetNumberOfCells(), nPoints = ug->GetNumberOfPoints();
        if (!cells || !cells->IsValid())
            detail::inputError(path, "cell offsets" + block + " are inconsistent with the connectivity");
        if (!types || types->GetNumberOfTuples() != nCells)
            detail::inputError(path, "has " + std::to_string(types ? types->GetNumberOfTuples() : 0) + " cell types"
                                     + block + " for " + std::to_string(nCells) + " cells");
        vtkNew<vtkIdList> ids;
        std::set<vtkIdType> cellPoints;
        for (vtkIdType c = 0; c < nCells; ++c) {
            const int type = types->GetValue(c);
            // The cell's name for a message, built only when there is one to give (10 M cells).
            auto where = [&] { return "cell " + std::to_string(c) + block; };
            auto named = [&] { return where() + " (" + vtkCellTypes::GetClassNameFromTypeId(type) + ")"; };
            const std::optional<int> want = pointsOfCellType(type);
            if (!want)
                detail::inputError(path, where() + " has VTK cell type " + std::to_string(type) + " ("
                                         + vtkCellTypes::GetClassNameFromTypeId(type)
                                         + "), which licvdb does not read: linear and quadratic cells are supported");
            cells->GetCellAtId(c, ids);
            const vtkIdType count = ids->GetNumberOfIds();
            if (*want != kVariable && count != *want)
                detail::inputError(path, named() + " has " + std::to_string(count) + " points; the type needs "
                                         + std::to_string(*want));
            if (*want == kVariable && count < 1) detail::inputError(path, named() + " has no points");
            for (vtkIdType k = 0; k < count; ++k)
                if (ids->GetId(k) < 0 || ids->GetId(k) >= nPoints)
                    detail::inputError(path, where() + " refers to point " + std::to_string(ids->GetId(k)) + "; the mesh"
                                             + block + " has " + std::to_string(nPoints) + " points");
            if (type == VTK_POLYHEDRON) {
                cellPoints.clear();
                cellPoints.insert(ids->begin(), ids->end());
                checkPolyhedronFaces(ug, c, cellPoints, block, path);
            }
        }
    }
}

} // namespace

std::string chooseVelocity(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& wanted,
                           const std::string& path)
{
    std::map<std::string, int> components; // name -> components, over all blocks
    for (const auto& ds : leaves)
        for (vtkDataSetAttributes* attrs : {static_cast<vtkDataSetAttributes*>(ds->GetPointData()),
                                            static_cast<vtkDataSetAttributes*>(ds->GetCellData())})
            for (int a = 0; a < attrs->GetNumberOfArrays(); ++a)
                if (vtkDataArray* arr = attrs->GetArray(a); arr && !internalArray(arr->GetName()))
                    components[arr->GetName()] = arr->GetNumberOfComponents();
    auto list = [&] {
        std::string s;
        for (const auto& [n, c] : components) s += (s.empty() ? "" : ", ") + n + " (" + std::to_string(c) + ")";
        return s.empty() ? std::string("no data arrays") : s;
    };
    std::string name;
    if (!wanted.empty()) {
        const auto it = components.find(wanted);
        if (it == components.end()) detail::inputError(path, "has no array named " + q(wanted) + "; its arrays are " + list());
        if (it->second != 3)
            detail::inputError(path, "array " + q(wanted) + " has " + std::to_string(it->second)
                                     + " component(s); a velocity needs 3");
        name = wanted;
    } else {
        std::vector<std::string> vectors;
        for (const auto& [n, c] : components)
            if (c == 3) vectors.push_back(n);
        for (const char* preferred : {"u", "velocity", "vel", "v"})
            for (const auto& n : vectors)
                if (name.empty() && lower(n) == preferred) name = n;
        if (name.empty() && vectors.size() == 1) name = vectors.front();
        if (name.empty() && vectors.empty())
            detail::inputError(path, "has no 3-component array to use as the velocity; its arrays are " + list());
        if (name.empty())
            detail::inputError(path, "has several vector arrays and none is named U, velocity, vel or v: " + list()
                                     + "; choose one with --grid NAME");
    }
    for (std::size_t b = 0; b < leaves.size(); ++b)
        if (!leaves[b]->GetPointData()->GetArray(name.c_str()) && !leaves[b]->GetCellData()->GetArray(name.c_str()))
            detail::inputError(path, "block " + std::to_string(b) + " of " + std::to_string(leaves.size())
                                     + " has no array " + q(name) + " (every block must carry the velocity)");
    return name;
}

std::uint64_t checkVelocityValues(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves, const std::string& name,
                                  const std::string& nanPolicy, const std::string& path)
{
    std::uint64_t bad = 0;
    std::string first;
    for (const auto& ds : leaves)
        for (int onCells = 0; onCells < 2; ++onCells) {
            vtkDataArray* arr = onCells ? ds->GetCellData()->GetArray(name.c_str()) : ds->GetPointData()->GetArray(name.c_str());
            if (!arr) continue;
            for (vtkIdType t = 0; t < arr->GetNumberOfTuples(); ++t)
                for (int c = 0; c < 3; ++c) {
                    const double v = arr->GetComponent(t, c);
                    if (std::isfinite(v)) continue;
                    if (bad++ == 0)
                        first = std::string(onCells ? "cell " : "point ") + std::to_string(t);
                    if (nanPolicy == "zero") arr->SetComponent(t, c, 0.0);
                }
        }
    if (bad && nanPolicy != "zero")
        detail::inputError(path, "velocity " + q(name) + " has " + std::to_string(bad) + " NaN/Inf value(s), the first at "
                                 + first + "; pass --nan zero to replace them with 0");
    return bad;
}

/// The cube root of each cell's bounding-box volume (its largest edge for a flat cell), over a
/// sample of at most ~200 000 cells, sorted.
std::vector<double> cellSizes(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves)
{
    vtkIdType total = 0;
    for (const auto& ds : leaves) total += ds->GetNumberOfCells();
    const vtkIdType step = std::max<vtkIdType>(1, total / 200000);
    std::vector<double> sizes;
    double b[6];
    for (const auto& ds : leaves)
        for (vtkIdType c = 0; c < ds->GetNumberOfCells(); c += step) {
            ds->GetCellBounds(c, b);
            const double dx = b[1] - b[0], dy = b[3] - b[2], dz = b[5] - b[4];
            const double vol = dx * dy * dz;
            const double s = vol > 0 ? std::cbrt(vol) : std::max({dx, dy, dz});
            if (s > 0 && std::isfinite(s)) sizes.push_back(s);
        }
    std::sort(sizes.begin(), sizes.end());
    return sizes;
}

/// The median over (a sample of) the cells of the cube root of each cell's bounding-box volume
/// (its largest edge for a flat box): the edge of a hexahedron, and of the cube a tetrahedron
/// was cut from.
double medianCellSize(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves)
{
    const std::vector<double> sizes = cellSizes(leaves); // sorted
    return sizes.empty() ? 0 : sizes[sizes.size() / 2];
}

std::array<std::array<double, 3>, 2> boundsOf(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves)
{
    std::array<std::array<double, 3>, 2> box{{{HUGE_VAL, HUGE_VAL, HUGE_VAL}, {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL}}};
    double b[6];
    for (const auto& ds : leaves) {
        ds->GetBounds(b);
        for (int a = 0; a < 3; ++a) {
            box[0][a] = std::min(box[0][a], b[2 * a]);
            box[1][a] = std::max(box[1][a], b[2 * a + 1]);
        }
    }
    return box;
}
Mesh readMesh(const std::string& path, const std::string& format, const MeshOptions& options, bool describing)
{
    Mesh m;
    m.report.describing = describing;
    m.data = readSingle(path, format, options, m.time, m.times, m.report);
    if (!m.data) detail::inputError(path, "VTK read nothing");
    m.leaves = leavesOf(m.data);
    if (m.leaves.empty())
        detail::inputError(path, "has no cells" + std::string(m.time ? " at time " + num(*m.time) : "")
                                 + "; expected " + describeFormat(format) + " with volume cells");
    checkTupleCounts(m.leaves, path);
    checkPoints(m.leaves, path);
    checkCells(m.leaves, path);
    const auto box = boundsOf(m.leaves);
    for (int a = 0; a < 3; ++a)
        if (!(box[1][a] > box[0][a]))
            detail::inputError(path, std::string("is flat: its bounds have zero extent along ") + "xyz"[a]
                                     + " (a 2D mesh cannot hold a 3D flow)");
    return m;
}

} // namespace vdbexport::mesh_module

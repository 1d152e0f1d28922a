// CFD meshes through VTK: its readers parse the files, vtkResampleToImage (VTK's probe) samples
// them on the VDB lattice, and this file turns the samples inside the mesh into grids. Built as
// licvdb's mesh module, licvdb-mesh.so (MeshModuleApi.h), which licvdb loads on first use; the
// functions of MeshInput.h (MeshInput.cpp) read the mesh in a child process first, then call these.
#include "MeshModuleApi.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <vtkCallbackCommand.h>
#include <vtkCellData.h>
#include <vtkCellArray.h>
#include <vtkCellDataToPointData.h>
#include <vtkCellType.h>
#include <vtkCellTypes.h>
#include <vtkCommand.h>
#include <vtkCompositeDataIterator.h>
#include <vtkCompositeDataSet.h>
#include <vtkDataArray.h>
#include <vtkDataSet.h>
#include <vtkDoubleArray.h>
#include <vtkIdList.h>
#include <vtkIdTypeArray.h>
#include <vtkGenericDataObjectReader.h>
#include <vtkImageData.h>
#include <vtkLogger.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkMultiBlockPLOT3DReader.h>
#include <vtkNew.h>
#include <vtkObjectFactory.h>
#include <vtkOpenFOAMReader.h>
#include <vtkOutputWindow.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkResampleToImage.h>
#include <vtkSmartPointer.h>
#include <vtkStructuredGrid.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>
#include <vtkXMLMultiBlockDataReader.h>
#include <vtkXMLPartitionedDataSetCollectionReader.h>
#include <vtkXMLStructuredGridReader.h>
#include <vtkXMLUnstructuredGridReader.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace {

/// A number as a user writes it: up to 6 significant digits, no trailing zeros.
std::string num(double v)
{
    std::ostringstream o;
    o.precision(6);
    o << v;
    return o.str();
}

// ---- VTK's messages ---------------------------------------------------------------------------

/// VTK reports problems (a truncated file, a bad tag) on its output window, not by exceptions:
/// this window keeps the text so a read can turn errors into one InputError, and keeps VTK quiet.
class CaptureWindow : public vtkOutputWindow
{
public:
    static CaptureWindow* New();
    vtkTypeMacro(CaptureWindow, vtkOutputWindow)

    void DisplayText(const char* text) override { add(mOther, text); }
    void DisplayErrorText(const char* text) override { add(mErrors, text); }
    void DisplayWarningText(const char* text) override { add(mOther, text); }
    void DisplayGenericWarningText(const char* text) override { add(mOther, text); }

    void clear()
    {
        std::lock_guard lock(mMutex);
        mErrors.clear();
        mOther.clear();
    }
    std::string errors()
    {
        std::lock_guard lock(mMutex);
        return mErrors;
    }

private:
    void add(std::string& to, const char* text)
    {
        std::lock_guard lock(mMutex);
        if (to.size() < 64 * 1024) to += text ? text : "";
    }
    std::mutex mMutex;
    std::string mErrors, mOther;
};
vtkStandardNewMacro(CaptureWindow);

CaptureWindow& captureWindow()
{
    static vtkSmartPointer<CaptureWindow> window = [] {
        auto w = vtkSmartPointer<CaptureWindow>::New();
        vtkOutputWindow::SetInstance(w);
        vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF); // VTK's log would repeat each error on stderr
        return w;
    }();
    return *window;
}

/// The first error VTK reported, without its "ERROR: In file, line N / vtkClass (0x...): " prefix.
std::string firstError(const std::string& text)
{
    std::istringstream in(text);
    std::string line, message;
    while (std::getline(in, line)) {
        if (line.rfind("ERROR:", 0) == 0 || line.rfind("Generic Warning", 0) == 0) continue;
        const auto colon = line.find("): ");
        message = colon != std::string::npos && line.rfind("vtk", 0) == 0 ? line.substr(colon + 3) : line;
        while (!message.empty() && std::isspace(static_cast<unsigned char>(message.back()))) message.pop_back();
        if (!message.empty()) return message;
    }
    return "VTK reported an error";
}

/// Run `update` on `algorithm` and throw the first error VTK reported for it.
void runChecked(vtkAlgorithm* algorithm, const std::string& path, const std::string& what,
                const std::function<void()>& update)
{
    CaptureWindow& w = captureWindow();
    w.clear();
    update();
    const std::string errors = w.errors();
    if (!errors.empty() || algorithm->GetErrorCode() != 0)
        detail::inputError(path, "cannot be read as " + what + ": " + (errors.empty() ? "read error" : firstError(errors)));
}

// ---- reading ----------------------------------------------------------------------------------

std::string lower(std::string s)
{
    for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

std::string describeFormat(const std::string& format)
{
    if (format == "vtu") return "a VTK XML unstructured grid (.vtu)";
    if (format == "vts") return "a VTK XML structured grid (.vts)";
    if (format == "vtm") return "a VTK XML multi-block data set (.vtm)";
    if (format == "vtpc") return "a VTK XML partitioned data set collection (.vtpc)";
    if (format == "pvd") return "a ParaView data collection (.pvd)";
    if (format == "vtk-mesh") return "a legacy VTK unstructured or structured grid (.vtk)";
    if (format == "plot3d") return "a PLOT3D grid and solution (.xyz + .q)";
    if (format == "openfoam") return "an OpenFOAM case";
    return "a mesh";
}

void requireFile(const std::string& path, const std::string& what)
{
    std::error_code ec;
    const auto st = fs::status(path, ec);
    if (!fs::exists(st)) throw lic::InputError("file " + q(path) + " not found; expected " + what);
    if (!fs::is_regular_file(st)) throw lic::InputError(q(path) + " is not a regular file; expected " + what);
    if (fs::file_size(path, ec) == 0) throw lic::InputError("file " + q(path) + " is empty (0 bytes); expected " + what);
}

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

/// One dataset of a .pvd collection.
struct PvdEntry
{
    double time = 0;
    std::string file;
};

std::vector<PvdEntry> parsePvd(const std::string& path)
{
    requireFile(path, describeFormat("pvd"));
    vtkNew<vtkXMLDataParser> parser;
    parser->SetFileName(path.c_str());
    CaptureWindow& w = captureWindow();
    w.clear();
    if (!parser->Parse())
        detail::inputError(path, "is not a valid .pvd (XML) file: " + firstError(w.errors()));
    vtkXMLDataElement* root = parser->GetRootElement();
    if (!root || std::string(root->GetName()) != "VTKFile" || !root->GetAttribute("type")
        || std::string(root->GetAttribute("type")) != "Collection")
        detail::inputError(path, "is not a .pvd collection (expected <VTKFile type=\"Collection\">)");
    vtkXMLDataElement* coll = root->FindNestedElementWithName("Collection");
    if (!coll) detail::inputError(path, "has no <Collection> element");
    std::vector<PvdEntry> entries;
    const fs::path dir = fs::path(path).parent_path();
    for (int i = 0; i < coll->GetNumberOfNestedElements(); ++i) {
        vtkXMLDataElement* e = coll->GetNestedElement(i);
        if (std::string(e->GetName()) != "DataSet") continue;
        const char* file = e->GetAttribute("file");
        if (!file || !*file) detail::inputError(path, "DataSet " + std::to_string(i) + " has no file attribute");
        PvdEntry entry;
        if (!e->GetScalarAttribute("timestep", entry.time)) entry.time = 0;
        if (!std::isfinite(entry.time)) detail::inputError(path, "DataSet " + std::to_string(i) + " has a non-finite timestep");
        entry.file = fs::path(file).is_absolute() ? std::string(file) : (dir / file).string();
        entries.push_back(entry);
    }
    if (entries.empty()) detail::inputError(path, "lists no DataSet");
    return entries;
}

std::vector<double> sortedUnique(std::vector<double> t)
{
    std::sort(t.begin(), t.end());
    t.erase(std::unique(t.begin(), t.end()), t.end());
    return t;
}

/// The time to read among `times`: options.time (which must be one of them, to 1e-9 relative) or
/// the latest.
double chooseTime(const std::vector<double>& times, const std::optional<double>& wanted, const std::string& path)
{
    if (!wanted) return times.back();
    for (double t : times)
        if (std::abs(t - *wanted) <= 1e-9 * std::max(1.0, std::abs(t))) return t;
    std::string list;
    for (std::size_t i = 0; i < times.size() && i < 20; ++i) list += (i ? ", " : "") + num(times[i]);
    if (times.size() > 20) list += ", …";
    detail::inputError(path, "has no time " + num(*wanted) + "; its times are " + list);
}

vtkSmartPointer<vtkDataObject> readSingle(const std::string& path, const std::string& format, const MeshOptions& options,
                                          std::optional<double>& timeRead, std::vector<double>& times);

template<typename ReaderT>
vtkSmartPointer<vtkDataObject> readFile(const std::string& path, const std::string& format)
{
    requireFile(path, describeFormat(format));
    vtkNew<ReaderT> reader;
    reader->SetFileName(path.c_str());
    runChecked(reader, path, describeFormat(format), [&] { reader->Update(); });
    return reader->GetOutputDataObject(0);
}

bool looksAscii(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    char buf[256];
    in.read(buf, sizeof buf);
    const auto n = in.gcount();
    for (std::streamsize i = 0; i < n; ++i) {
        const unsigned char c = static_cast<unsigned char>(buf[i]);
        if (!(std::isdigit(c) || std::isspace(c) || c == '.' || c == '-' || c == '+' || c == 'e' || c == 'E'
              || c == 'd' || c == 'D'))
            return false;
    }
    return n > 0;
}

vtkSmartPointer<vtkDataObject> readPlot3d(const std::string& path, const MeshOptions& options)
{
    requireFile(path, "a PLOT3D grid (.xyz) file");
    std::string qfile = options.solution;
    if (qfile.empty()) qfile = fs::path(path).replace_extension(".q").string();
    requireFile(qfile, "a PLOT3D solution (.q) file beside the grid (or name it: --solution FILE)");
    vtkNew<vtkMultiBlockPLOT3DReader> r;
    r->SetXYZFileName(path.c_str());
    r->SetQFileName(qfile.c_str());
    if (looksAscii(path)) {
        r->BinaryFileOff();
    } else {
        r->AutoDetectFormatOn(); // byte order, precision, Fortran record markers, multi-grid, blanking
    }
    r->AddFunction(200); // velocity = momentum / density
    runChecked(r, path, describeFormat("plot3d"), [&] { r->Update(); });
    return r->GetOutputDataObject(0);
}

/// What VTK's reader of `format` gives for the one file `path`; nothing for a format that is not
/// one file read by one VTK reader (pvd, plot3d, openfoam). The others are what a .pvd may list.
std::optional<vtkSmartPointer<vtkDataObject>> readOneFile(const std::string& path, const std::string& format)
{
    if (format == "vtu") return readFile<vtkXMLUnstructuredGridReader>(path, format);
    if (format == "vts") return readFile<vtkXMLStructuredGridReader>(path, format);
    if (format == "vtm") return readFile<vtkXMLMultiBlockDataReader>(path, format);
    if (format == "vtpc") return readFile<vtkXMLPartitionedDataSetCollectionReader>(path, format);
    if (format == "vtk-mesh") return readFile<vtkGenericDataObjectReader>(path, format);
    return std::nullopt;
}

/// What the reader of `format` gives for `path`: the time read and the series' times (sorted) are
/// set for a series (pvd, openfoam), left empty otherwise.
vtkSmartPointer<vtkDataObject> readSingle(const std::string& path, const std::string& format, const MeshOptions& options,
                                          std::optional<double>& timeRead, std::vector<double>& times)
{
    if (auto data = readOneFile(path, format)) return *data;
    if (format == "plot3d") return readPlot3d(path, options);
    if (format == "openfoam") {
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
    if (format == "pvd") {
        const auto entries = parsePvd(path);
        for (const auto& e : entries) times.push_back(e.time);
        times = sortedUnique(times);
        const double t = chooseTime(times, options.time, path);
        timeRead = t;
        auto blocks = vtkSmartPointer<vtkMultiBlockDataSet>::New();
        unsigned n = 0;
        for (const auto& e : entries) {
            if (e.time != t) continue;
            const std::string ext = lower(fs::path(e.file).extension().string());
            const std::string meshFormat = ext == ".vtk" ? "vtk-mesh" : ext.empty() ? "" : ext.substr(1);
            auto block = readOneFile(e.file, meshFormat);
            if (!block)
                detail::inputError(path, "lists " + q(e.file) + ", which is not a mesh file (.vtu, .vts, .vtm, .vtpc, .vtk)");
            blocks->SetBlock(n++, *block);
        }
        return blocks;
    }
    throw lic::InputError("unknown mesh format " + q(format));
}

// ---- checking ---------------------------------------------------------------------------------

/// The non-empty datasets of what a reader gave (a dataset, or the leaves of a composite).
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

/// The velocity array's name: `wanted`, or U / velocity / vel / v (any case), or the only
/// 3-component array. It must be in every block.
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

/// NaN/Inf in the velocity: refused with the first offender, or set to zero.
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

/// The median over (a sample of) the cells of the cube root of each cell's bounding-box volume
/// (its largest edge for a flat box): the edge of a hexahedron, and of the cube a tetrahedron
/// was cut from.
double medianCellSize(const std::vector<vtkSmartPointer<vtkDataSet>>& leaves)
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
    if (sizes.empty()) return 0;
    auto mid = sizes.begin() + std::ptrdiff_t(sizes.size() / 2);
    std::nth_element(sizes.begin(), mid, sizes.end());
    return *mid;
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

/// A read mesh, checked.
struct Mesh
{
    vtkSmartPointer<vtkDataObject> data;
    std::vector<vtkSmartPointer<vtkDataSet>> leaves;
    std::optional<double> time;
    std::vector<double> times;
};

Mesh readMesh(const std::string& path, const std::string& format, const MeshOptions& options)
{
    Mesh m;
    m.data = readSingle(path, format, options, m.time, m.times);
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

} // namespace

std::vector<double> meshTimes(const std::string& path, const std::string& format)
{
    if (format == "pvd") {
        std::vector<double> t;
        for (const auto& e : parsePvd(path)) t.push_back(e.time);
        return sortedUnique(t);
    }
    if (format == "openfoam") {
        auto r = openFoamReader(path);
        std::vector<double> t;
        vtkDoubleArray* tv = r->GetTimeValues();
        for (vtkIdType i = 0; tv && i < tv->GetNumberOfTuples(); ++i) t.push_back(tv->GetValue(i));
        return sortedUnique(t);
    }
    return {};
}

MeshSummary describeMesh(const std::string& path, const std::string& format, const MeshOptions& options)
{
    const Mesh m = readMesh(path, format, options);
    MeshSummary s;
    s.format = format;
    s.blocks = m.leaves.size();
    for (const auto& ds : m.leaves) {
        s.cells += std::uint64_t(ds->GetNumberOfCells());
        s.points += std::uint64_t(ds->GetNumberOfPoints());
    }
    s.bounds = boundsOf(m.leaves);
    s.medianCellSize = medianCellSize(m.leaves);
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

/// Cell arrays without a point array of the same name averaged to the points (VTK's
/// vtkCellDataToPointData), per block; point arrays kept as they are (an OpenFOAM reader's point
/// data already use the boundary patches' values).
vtkSmartPointer<vtkDataObject> withPointData(const Mesh& m, bool& averaged)
{
    averaged = false;
    auto needsAveraging = [](vtkDataSet* ds) {
        for (int a = 0; a < ds->GetCellData()->GetNumberOfArrays(); ++a) {
            const char* name = ds->GetCellData()->GetArrayName(a);
            if (!internalArray(name) && !ds->GetPointData()->GetArray(name)) return true;
        }
        return false;
    };
    for (const auto& ds : m.leaves) averaged = averaged || needsAveraging(ds);
    if (!averaged && m.leaves.size() == 1) return m.leaves.front().GetPointer();
    auto blocks = vtkSmartPointer<vtkMultiBlockDataSet>::New();
    unsigned n = 0;
    for (const auto& ds : m.leaves) {
        if (!needsAveraging(ds)) {
            blocks->SetBlock(n++, ds);
            continue;
        }
        vtkNew<vtkCellDataToPointData> c2p;
        c2p->SetInputData(ds);
        c2p->PassCellDataOff();
        c2p->ProcessAllArraysOn();
        c2p->Update();
        vtkSmartPointer<vtkDataSet> out = c2p->GetOutput();
        for (int a = 0; a < ds->GetPointData()->GetNumberOfArrays(); ++a)
            out->GetPointData()->AddArray(ds->GetPointData()->GetAbstractArray(a)); // the file's own win
        blocks->SetBlock(n++, out);
    }
    return blocks;
}

struct ProgressClient
{
    const std::function<bool(double)>* callback;
    bool cancelled = false;
};

void onProgress(vtkObject* caller, unsigned long, void* client, void* data)
{
    auto* c = static_cast<ProgressClient*>(client);
    if (!c->callback || !*c->callback || !data || c->cancelled) return;
    if (!(*c->callback)(*static_cast<double*>(data))) {
        c->cancelled = true;
        if (auto* algorithm = vtkAlgorithm::SafeDownCast(caller)) algorithm->SetAbortExecute(1);
    }
}

} // namespace

namespace {

/// The lattice the mesh is resampled onto: voxel (0,0,0) at the low corner of the (cropped)
/// bounds, `h` apart.
struct Lattice
{
    std::array<std::array<double, 3>, 2> box;
    double h = 0;
    std::array<int, 3> dims{};
};

Lattice chooseLattice(const Mesh& m, const MeshOptions& options, const std::string& path)
{
    Lattice l;
    l.box = boundsOf(m.leaves);
    if (options.crop) {
        for (int a = 0; a < 3; ++a) {
            l.box[0][a] = std::max(l.box[0][a], (*options.crop)[0][a]);
            l.box[1][a] = std::min(l.box[1][a], (*options.crop)[1][a]);
            if (!(l.box[1][a] > l.box[0][a]))
                detail::inputError(path, std::string("the crop box misses the mesh along ") + "xyz"[a]);
        }
    }
    l.h = options.voxelSize ? *options.voxelSize : medianCellSize(m.leaves);
    if (!(l.h > 0) || !std::isfinite(l.h)) detail::inputError(path, "has degenerate cells (zero size): pass --voxel-size");
    double voxels = 1;
    for (int a = 0; a < 3; ++a) {
        const double n = std::floor((l.box[1][a] - l.box[0][a]) / l.h + 1e-9) + 1;
        voxels *= n;
        l.dims[a] = n < 2e9 ? int(n) : 0;
    }
    const double maxVoxels = double(std::min<std::uint64_t>(options.maxVoxels, kMaxDenseVoxels));
    if (voxels > maxVoxels || l.dims[0] == 0 || l.dims[1] == 0 || l.dims[2] == 0) {
        const double hMin = l.h * std::cbrt(voxels / maxVoxels) * 1.01;
        detail::inputError(path, "resampling at voxel size " + num(l.h) + " makes " + num(voxels)
                                 + " voxels, more than the limit of " + num(maxVoxels) + "; pass --voxel-size "
                                 + num(hMin) + " or larger, or --crop a smaller box");
    }
    return l;
}

/// VTK's probe of `input` at every lattice point (vtkResampleToImage), with progress.
vtkSmartPointer<vtkImageData> probe(vtkDataObject* input, const Lattice& l, const MeshOptions& options,
                                    const std::string& path, const std::string& format, std::string& maskName)
{
    vtkNew<vtkResampleToImage> resample;
    resample->SetInputDataObject(input);
    resample->UseInputBoundsOff();
    resample->SetSamplingBounds(l.box[0][0], l.box[0][0] + (l.dims[0] - 1) * l.h, l.box[0][1],
                                l.box[0][1] + (l.dims[1] - 1) * l.h, l.box[0][2], l.box[0][2] + (l.dims[2] - 1) * l.h);
    resample->SetSamplingDimensions(l.dims[0], l.dims[1], l.dims[2]);
    ProgressClient client{&options.progress};
    vtkNew<vtkCallbackCommand> progress;
    progress->SetCallback(onProgress);
    progress->SetClientData(&client);
    resample->AddObserver(vtkCommand::ProgressEvent, progress);
    runChecked(resample, path, describeFormat(format), [&] { resample->Update(); });
    if (client.cancelled) throw lic::Cancelled();
    maskName = resample->GetMaskArrayName();
    vtkSmartPointer<vtkImageData> image = resample->GetOutput();
    return image;
}

/// The probed values inside the mesh as grids: the velocity and one float grid per scalar array.
/// @return the number of active voxels.
std::uint64_t gridsFromImage(vtkImageData* image, const std::string& maskName, const Lattice& l,
                             const std::string& velocityName, const std::string& path, LoadedField& out)
{
    vtkDataArray* mask = image->GetPointData()->GetArray(maskName.c_str());
    vtkDataArray* vel = image->GetPointData()->GetArray(velocityName.c_str());
    if (!mask || !vel) detail::inputError(path, "VTK's resampling lost the array " + q(velocityName));
    openvdb::Mat4d mat = openvdb::Mat4d::identity();
    mat.setToScale(openvdb::Vec3d(l.h));
    mat.setTranslation(openvdb::Vec3d(l.box[0][0], l.box[0][1], l.box[0][2]));
    const auto xform = openvdb::math::Transform::createLinearTransform(mat);
    out.velocity = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    out.velocity->setTransform(xform->copy());
    std::vector<std::pair<vtkDataArray*, openvdb::FloatGrid::Ptr>> scalars;
    for (int a = 0; a < image->GetPointData()->GetNumberOfArrays(); ++a) {
        vtkDataArray* arr = image->GetPointData()->GetArray(a);
        if (!arr || arr->GetNumberOfComponents() != 1 || internalArray(arr->GetName())) continue;
        auto g = openvdb::FloatGrid::create(0.0f);
        g->setTransform(xform->copy());
        g->setName(arr->GetName());
        scalars.emplace_back(arr, g);
    }
    auto vacc = out.velocity->getAccessor();
    std::vector<openvdb::FloatGrid::Accessor> saccs;
    for (auto& [arr, g] : scalars) saccs.push_back(g->getAccessor());
    std::uint64_t active = 0;
    const vtkIdType nx = l.dims[0], ny = l.dims[1];
    for (int k = 0; k < l.dims[2]; ++k)
        for (int j = 0; j < l.dims[1]; ++j)
            for (int i = 0; i < l.dims[0]; ++i) {
                const vtkIdType id = i + nx * (j + ny * vtkIdType(k));
                if (mask->GetComponent(id, 0) == 0) continue;
                const openvdb::Coord ijk(i, j, k);
                vacc.setValueOn(ijk, openvdb::Vec3s(float(vel->GetComponent(id, 0)), float(vel->GetComponent(id, 1)),
                                                    float(vel->GetComponent(id, 2))));
                for (std::size_t s = 0; s < scalars.size(); ++s)
                    saccs[s].setValueOn(ijk, float(scalars[s].first->GetComponent(id, 0)));
                ++active;
            }
    for (auto& [arr, g] : scalars) {
        g->pruneGrid();
        out.scalars.emplace(arr->GetName(), g);
    }
    return active;
}

} // namespace

LoadedField loadMesh(const std::string& path, const std::string& format, const MeshOptions& options,
                     const std::string& nanPolicy)
{
    openvdb::initialize();
    Mesh m = readMesh(path, format, options);
    const std::string velocityName = chooseVelocity(m.leaves, options.vectorName, path);
    LoadedField out;
    out.format = format;
    out.nonFiniteReplaced = checkVelocityValues(m.leaves, velocityName, nanPolicy, path);
    const Lattice l = chooseLattice(m, options, path);
    bool averaged = false;
    const vtkSmartPointer<vtkDataObject> input = withPointData(m, averaged);
    std::string maskName;
    const vtkSmartPointer<vtkImageData> image = probe(input, l, options, path, format, maskName);
    const std::uint64_t active = gridsFromImage(image, maskName, l, velocityName, path, out);
    if (active == 0)
        detail::inputError(path, "no voxel centre at voxel size " + num(l.h)
                                 + " lies inside a volume cell of the mesh (a surface mesh, or cells smaller than a voxel "
                                   "and between voxel centres: pass a smaller --voxel-size)");

    out.velocity->setName(velocityName);
    out.velocity->setGridClass(openvdb::GRID_UNKNOWN);
    out.velocity->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    out.gridName = velocityName;
    auto tag = [&](openvdb::GridBase& g, const std::string& array) {
        g.insertMeta("source", openvdb::StringMetadata(path));
        g.insertMeta("source_format", openvdb::StringMetadata(format));
        g.insertMeta("source_array", openvdb::StringMetadata(array));
        if (m.time) g.insertMeta("source_time", openvdb::DoubleMetadata(*m.time));
    };
    tag(*out.velocity, velocityName);
    for (auto& [name, g] : out.scalars) tag(*g, name);

    std::uint64_t cells = 0;
    for (const auto& ds : m.leaves) cells += std::uint64_t(ds->GetNumberOfCells());
    std::ostringstream note;
    note << "resampled " << cells << " cells" << (m.leaves.size() > 1 ? " in " + std::to_string(m.leaves.size()) + " blocks" : "")
         << (m.time ? " at time " + num(*m.time) : "") << " onto " << l.dims[0] << "x" << l.dims[1] << "x" << l.dims[2]
         << " voxels of size " << num(l.h) << (options.voxelSize ? "" : " (the median cell size; --voxel-size to change)")
         << ": " << active << " inside the mesh";
    out.notes.push_back(note.str());
    if (averaged) out.notes.push_back("cell data were averaged to the mesh points, then interpolated within cells");
    if (out.nonFiniteReplaced)
        out.notes.push_back("replaced " + std::to_string(out.nonFiniteReplaced) + " NaN/Inf velocity components with 0");
    return out;
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

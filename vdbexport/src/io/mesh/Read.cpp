// Reading each mesh format with VTK's readers: one file (.vtu, .vts, .vtm, .vtpc, legacy .vtk),
// a .pvd collection (a time series of those), PLOT3D grid + solution; OpenFOAM in OpenFoam*.cpp.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <vtkGenericDataObjectReader.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkMultiBlockPLOT3DReader.h>
#include <vtkNew.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>
#include <vtkXMLMultiBlockDataReader.h>
#include <vtkXMLPartitionedDataSetCollectionReader.h>
#include <vtkXMLStructuredGridReader.h>
#include <vtkXMLUnstructuredGridReader.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace {

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
    clearVtkErrors();
    if (!parser->Parse())
        detail::inputError(path, "is not a valid .pvd (XML) file: " + firstError(vtkErrors()));
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

} // namespace

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

std::vector<double> sortedUnique(std::vector<double> t)
{
    std::sort(t.begin(), t.end());
    t.erase(std::unique(t.begin(), t.end()), t.end());
    return t;
}

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
                                          std::optional<double>& timeRead, std::vector<double>& times,
                                          ReadReport& report)
{
    if (auto data = readOneFile(path, format)) return *data;
    if (format == "plot3d") return readPlot3d(path, options);
    if (format == "openfoam") return readOpenFoam(path, options, timeRead, times, report);
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

std::vector<double> meshTimes(const std::string& path, const std::string& format)
{
    if (format == "pvd") {
        std::vector<double> t;
        for (const auto& e : parsePvd(path)) t.push_back(e.time);
        return sortedUnique(t);
    }
    if (format == "openfoam") return openFoamTimes(path);
    return {};
}

} // namespace vdbexport::mesh_module

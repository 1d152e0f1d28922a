// The table of input formats (InputFormats.h) and the look-ups that read it.
#include "vdbexport/io/InputFormats.h"
#include "vdbexport/io/FieldInput.h"

#include "io/Quote.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

namespace vdbexport {

using detail::q;

namespace {

DenseImage readNpy(std::string_view bytes, const FieldSpec&, const std::string& source) { return parseNpy(bytes, source); }
DenseImage readVti(std::string_view bytes, const FieldSpec&, const std::string& source) { return parseVti(bytes, source); }
DenseImage readVtk(std::string_view bytes, const FieldSpec&, const std::string& source)
{
    return parseLegacyVtk(bytes, source);
}
DenseImage readRaw(std::string_view bytes, const FieldSpec& spec, const std::string& source)
{
    const auto& s = *spec.shape; // loadField checks that it is set (needsShape)
    return parseRaw(bytes, {std::int64_t(s[0]), std::int64_t(s[1]), std::int64_t(s[2])}, spec.dtype, source);
}

/// A directory holding system/controlDict, or that file itself.
bool isOpenFoamCase(const std::string& path)
{
    std::error_code ec;
    if (fs::is_directory(path, ec) && fs::exists(fs::path(path) / "system" / "controlDict", ec)) return true;
    return fs::path(path).filename() == "controlDict";
}

/// A legacy VTK file whose DATASET is an unstructured, structured or rectilinear grid (a mesh),
/// not STRUCTURED_POINTS (a dense image).
bool isLegacyVtkMesh(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    std::string head(1024, '\0');
    in.read(head.data(), std::streamsize(head.size()));
    head.resize(std::size_t(in.gcount()));
    for (auto& c : head) c = char(std::toupper(static_cast<unsigned char>(c)));
    const auto at = head.find("DATASET");
    if (at == std::string::npos) return false;
    const auto type = head.substr(at + 7, 40);
    return type.find("UNSTRUCTURED_GRID") != std::string::npos || type.find(" STRUCTURED_GRID") != std::string::npos
           || type.find("RECTILINEAR_GRID") != std::string::npos;
}

using K = InputKind;

/// The rows, in the order help and messages list them. A format sharing an extension with an
/// earlier row says how to tell its files apart (matchesContent).
const std::vector<InputFormat>& table()
{
    static const std::vector<InputFormat> formats{
        {.name = "vdb", .extensions = {".vdb"}, .kind = K::Grid, .description = "an OpenVDB .vdb file"},
        {.name = "npy", .extensions = {".npy"}, .kind = K::Dense, .parse = readNpy, .description = "a NumPy .npy file"},
        {.name = "vti", .extensions = {".vti"}, .kind = K::Dense, .parse = readVti,
         .description = "a VTK XML image data .vti file"},
        {.name = "vtk", .extensions = {".vtk"}, .kind = K::Dense, .parse = readVtk, .description = "a legacy VTK .vtk file"},
        {.name = "raw", .extensions = {".raw", ".bin", ".dat"}, .kind = K::Dense, .parse = readRaw,
         .description = "a raw binary field file", .needsShape = true},
        {.name = "vtu", .extensions = {".vtu"}, .kind = K::Mesh, .description = "a VTK XML unstructured grid (.vtu)"},
        {.name = "vts", .extensions = {".vts"}, .kind = K::Mesh, .description = "a VTK XML structured grid (.vts)"},
        {.name = "vtm", .extensions = {".vtm"}, .kind = K::Mesh, .description = "a VTK XML multi-block data set (.vtm)"},
        {.name = "vtpc", .extensions = {".vtpc"}, .kind = K::Mesh,
         .description = "a VTK XML partitioned data set collection (.vtpc)"},
        {.name = "pvd", .extensions = {".pvd"}, .kind = K::Mesh, .description = "a ParaView data collection (.pvd)"},
        {.name = "vtk-mesh", .extensions = {".vtk"}, .kind = K::Mesh,
         .description = "a legacy VTK unstructured or structured grid (.vtk)", .matchesContent = isLegacyVtkMesh},
        {.name = "plot3d", .extensions = {".xyz", ".p3d", ".x"}, .kind = K::Mesh,
         .description = "a PLOT3D grid and solution (.xyz + .q)"},
        {.name = "openfoam", .extensions = {".foam"}, .kind = K::Mesh, .description = "an OpenFOAM case",
         .matchesPath = isOpenFoamCase},
    };
    return formats;
}

std::string lower(std::string s)
{
    for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

bool sharesExtension(const InputFormat& a, const InputFormat& b)
{
    return std::any_of(a.extensions.begin(), a.extensions.end(), [&](const std::string& e) {
        return std::find(b.extensions.begin(), b.extensions.end(), e) != b.extensions.end();
    });
}

/// ".vdb, .npy, …, .raw/.bin/.dat, …, .foam or an OpenFOAM case": what formatFromPath recognises.
std::string knownExtensions()
{
    std::vector<std::string> seen, parts;
    for (const InputFormat& f : table()) {
        std::string part;
        for (const std::string& e : f.extensions) {
            if (std::find(seen.begin(), seen.end(), e) != seen.end()) continue;
            seen.push_back(e);
            part += (part.empty() ? "" : "/") + e;
        }
        if (f.matchesPath) part += (part.empty() ? "" : " or ") + f.description;
        if (!part.empty()) parts.push_back(part);
    }
    std::string out;
    for (const std::string& p : parts) out += (out.empty() ? "" : ", ") + p;
    return out;
}

std::string joinedNames(const std::vector<std::string>& names, const char* separator)
{
    std::string out;
    for (const std::string& n : names) out += (out.empty() ? "" : separator) + n;
    return out;
}

} // namespace

const char* kindName(InputKind kind)
{
    switch (kind) {
    case InputKind::Grid: return "grid";
    case InputKind::Dense: return "dense";
    case InputKind::Mesh: return "mesh";
    }
    return "?";
}

std::span<const InputFormat> inputFormats() { return table(); }

const InputFormat* findInputFormat(std::string_view name)
{
    for (const InputFormat& f : table())
        if (f.name == name) return &f;
    return nullptr;
}

std::string formatFromPath(const std::string& path)
{
    for (const InputFormat& f : table())
        if (f.matchesPath && f.matchesPath(path)) return f.name;
    const std::string ext = lower(fs::path(path).extension().string());
    for (const InputFormat& f : table())
        if (std::find(f.extensions.begin(), f.extensions.end(), ext) != f.extensions.end()) return f.name;
    std::vector<std::string> names;
    for (const InputFormat& f : table()) names.push_back(f.name);
    throw lic::InputError("cannot tell the format of " + q(path) + " from its extension '" + ext + "'; expected "
                          + knownExtensions() + ", or pass --format " + joinedNames(names, "|"));
}

std::string resolveInputFormat(const std::string& path, const std::string& format)
{
    const std::string name = format.empty() || format == "auto" ? formatFromPath(path) : format;
    const InputFormat* chosen = findInputFormat(name);
    if (!chosen)
        throw lic::InputError("unknown field format " + q(name) + " for " + q(path) + "; expected " + inputFormatHelp());
    bool later = false;
    for (const InputFormat& f : table()) {
        if (&f == chosen) later = true;
        else if (later && f.matchesContent && sharesExtension(f, *chosen) && f.matchesContent(path)) return f.name;
    }
    return name;
}

bool isMeshFormat(std::string_view name)
{
    const InputFormat* f = findInputFormat(name);
    return f && f->kind == InputKind::Mesh;
}

std::vector<std::string> inputFormatNames(InputKind kind)
{
    std::vector<std::string> names;
    for (const InputFormat& f : table())
        if (f.kind == kind) names.push_back(f.name);
    return names;
}

std::vector<std::string> inputFormatValues()
{
    std::vector<std::string> names{"auto"};
    for (const InputFormat& f : table()) names.push_back(f.name);
    return names;
}

std::string inputFormatHelp() { return joinedNames(inputFormatValues(), "|"); }

} // namespace vdbexport

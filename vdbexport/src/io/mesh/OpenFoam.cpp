// OpenFOAM cases through VTK's readers: the internal mesh and its fields at one time.
//
// Each read goes through a shadow case: a temporary directory (removed after the read, also on
// errors) of symlinks to the case's system/ and constant/, and a real directory for the time read,
// at the top level or in every processor*/ directory, holding symlinks to its field files except
// (a) files whose header `object` is not their file name (a stale U.orig with `object U;` would
// otherwise replace U: VTK names fields by `object`; "the field named U is the file U"), and
// (b) ASCII files with dictionary directives VTK cannot read (#includeEtc, `uniform $var`,
// boundaryField keyed by patch group), which get expanded copies (FoamDict.h). Gzipped and binary
// field files are linked as they are.
//
// Decomposed cases: the times are those of the top level and of the processor*/ directories (a
// time is in the processors when every one has it); a time is read from the processors when they
// have it (VTK's vtkPOpenFOAMReader, all processor directories in this process through a
// vtkDummyController), else from the top level, and the read's note says which. A time only some
// processors have is an error naming them: nothing falls back silently.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"
#include "io/mesh/FoamDict.h"

#include <lic/util/Error.h>

#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkDataArray.h>
#include <vtkDoubleArray.h>
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
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <unordered_map>

#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace {

thread_local ReadReport* tReport = nullptr;

void note(const std::string& text)
{
    if (tReport) tReport->notes.push_back(text);
}

void warn(const std::string& text)
{
    if (tReport) tReport->warnings.push_back(text);
}

std::string joinedList(const std::vector<std::string>& items, const std::string& sep = ", ", std::size_t most = 12)
{
    std::string s;
    for (std::size_t i = 0; i < items.size() && i < most; ++i) s += (i ? sep : "") + items[i];
    if (items.size() > most) s += sep + "… (" + std::to_string(items.size()) + " in all)";
    return s;
}

// ---- the case on disk -----------------------------------------------------------------------

/// The case directory of `path`: the directory itself, or the case of a `case.foam` / controlDict.
/// Checks that it has system/controlDict.
fs::path caseDirOf(const std::string& path)
{
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
        const fs::path dir(path);
        if (!fs::exists(dir / "system" / "controlDict", ec)) {
            const std::string name = fs::absolute(dir, ec).lexically_normal().filename().string();
            const fs::path parent = fs::absolute(dir, ec).lexically_normal().parent_path();
            if (name.rfind("processor", 0) == 0 && fs::exists(parent / "system" / "controlDict", ec))
                throw lic::InputError(q(path) + " is a processor directory of the decomposed OpenFOAM case " + q(parent.string())
                                      + ": pass the case directory (its processor directories are read together)");
            throw lic::InputError(q(path) + " is a directory but not an OpenFOAM case: it has no system/controlDict");
        }
        return dir;
    }
    if (!fs::exists(path, ec)) throw lic::InputError("OpenFOAM case " + q(path) + " not found");
    const fs::path dir = fs::path(path).filename() == "controlDict" ? fs::path(path).parent_path().parent_path()
                                                                      : fs::path(path).parent_path();
    if (!fs::exists(dir / "system" / "controlDict", ec))
        throw lic::InputError(q(path) + ": the OpenFOAM case " + q(dir.string()) + " has no system/controlDict");
    return dir.empty() ? fs::path(".") : dir;
}

/// The time value a directory name stands for: a plain decimal number ("0", "0.25", "1e-05").
std::optional<double> timeOfName(const std::string& name)
{
    if (name.empty() || name.find_first_of("xXnN") != std::string::npos || name[0] == '+') return std::nullopt;
    char* end = nullptr;
    const double v = std::strtod(name.c_str(), &end);
    if (end != name.c_str() + name.size() || !std::isfinite(v)) return std::nullopt;
    return v;
}

bool sameTime(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(1.0, std::abs(a)); }

struct TimeDir
{
    double value = 0;
    std::string name;
};

bool hasRegularFile(const fs::path& dir)
{
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec))
        if (e.is_regular_file(ec)) return true;
    return false;
}

/// The time directories of `dir` that hold at least one file (a field), sorted by time.
std::vector<TimeDir> timeDirsOf(const fs::path& dir)
{
    std::vector<TimeDir> out;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
        if (!e.is_directory(ec)) continue;
        const std::string name = e.path().filename().string();
        if (const auto t = timeOfName(name); t && hasRegularFile(e.path())) out.push_back({*t, name});
    }
    std::sort(out.begin(), out.end(), [](const TimeDir& a, const TimeDir& b) { return a.value < b.value; });
    return out;
}

const TimeDir* findTime(const std::vector<TimeDir>& dirs, double t)
{
    for (const auto& d : dirs)
        if (sameTime(d.value, t)) return &d;
    return nullptr;
}

/// Where a time of a case is read from.
enum class From { Processors, TopLevel, Incomplete };

struct FoamTime
{
    double value = 0;
    From from = From::TopLevel;
    std::optional<std::string> topName;          ///< its directory at the top level
    std::vector<std::string> procNames;          ///< its directory in each processor ("" where missing)
};

struct FoamCase
{
    fs::path dir;
    std::vector<std::string> processors; ///< processor0, processor1, … (by number)
    std::vector<FoamTime> times;         ///< sorted
};

FoamCase scanCase(const std::string& path)
{
    FoamCase c;
    c.dir = caseDirOf(path);
    std::error_code ec;
    std::vector<std::pair<long, std::string>> procs;
    bool collated = false;
    for (const auto& e : fs::directory_iterator(c.dir, ec)) {
        if (!e.is_directory(ec)) continue;
        const std::string name = e.path().filename().string();
        if (name.rfind("processor", 0) != 0) continue;
        const std::string rest = name.substr(9);
        if (!rest.empty() && std::all_of(rest.begin(), rest.end(), [](char ch) { return ch >= '0' && ch <= '9'; }))
            procs.emplace_back(std::strtol(rest.c_str(), nullptr, 10), name);
        else if (rest.rfind('s', 0) == 0)
            collated = true; // processors<N>, processors<N>_<a>-<b>: OpenFOAM's collated format
    }
    std::sort(procs.begin(), procs.end());
    for (auto& p : procs) c.processors.push_back(p.second);
    if (collated && c.processors.empty())
        detail::inputError(c.dir.string(), "is decomposed in OpenFOAM's collated format (processors<N>/), which VTK 9.1 "
                                           "cannot read: run reconstructPar, or decompose with "
                                           "`decomposePar -fileHandler uncollated` (processor0/, processor1/, …)");

    const std::vector<TimeDir> top = timeDirsOf(c.dir);
    std::vector<std::vector<TimeDir>> proc;
    for (const auto& p : c.processors) proc.push_back(timeDirsOf(c.dir / p));
    std::vector<double> all;
    for (const auto& d : top) all.push_back(d.value);
    for (const auto& list : proc)
        for (const auto& d : list) all.push_back(d.value);
    std::sort(all.begin(), all.end());
    std::vector<double> unique;
    for (double t : all)
        if (unique.empty() || !sameTime(unique.back(), t)) unique.push_back(t);
    for (double t : unique) {
        FoamTime ft;
        ft.value = t;
        if (const TimeDir* d = findTime(top, t)) ft.topName = d->name;
        std::size_t have = 0;
        for (const auto& list : proc) {
            const TimeDir* d = findTime(list, t);
            ft.procNames.push_back(d ? d->name : "");
            have += d != nullptr;
        }
        ft.from = !c.processors.empty() && have == c.processors.size() ? From::Processors
                  : ft.topName                                         ? From::TopLevel
                                                                       : From::Incomplete;
        c.times.push_back(ft);
    }
    return c;
}

std::vector<std::string> processorsWith(const FoamCase& c, const FoamTime& t, bool with)
{
    std::vector<std::string> out;
    for (std::size_t i = 0; i < c.processors.size(); ++i)
        if (t.procNames[i].empty() != with) out.push_back(c.processors[i]);
    return out;
}

std::string processorsText(const FoamCase& c)
{
    return std::to_string(c.processors.size()) + " processor director" + (c.processors.size() == 1 ? "y" : "ies");
}

/// Where time `t` is read from, for --list and notes.
std::string sourceText(const FoamCase& c, const FoamTime& t)
{
    switch (t.from) {
    case From::Processors:
        return processorsText(c) + (t.topName ? " (the top level has it too)" : "");
    case From::TopLevel: {
        if (c.processors.empty()) return "the top level";
        const auto with = processorsWith(c, t, true);
        return with.empty() ? "the top level (not in the processor directories)"
                            : "the top level (only " + joinedList(with) + " of " + processorsText(c) + " have it)";
    }
    case From::Incomplete:
        return "incomplete: only in " + joinedList(processorsWith(c, t, true)) + " of " + processorsText(c);
    }
    return "";
}

// ---- field files --------------------------------------------------------------------------

/// The entries of a FoamFile header that matter here.
struct FoamHeader
{
    bool found = false;
    std::string object, format, cls;
};

/// Read the `FoamFile { … }` header at the start of `file` (the first 8 kB; comments skipped).
FoamHeader readHeader(const fs::path& file)
{
    FoamHeader h;
    std::ifstream in(file, std::ios::binary);
    std::string buf(8192, '\0');
    in.read(buf.data(), std::streamsize(buf.size()));
    buf.resize(std::size_t(in.gcount()));
    // Tokens of the text without comments; ';', '{', '}' are tokens of their own.
    std::vector<std::string> tokens;
    std::string cur;
    auto flush = [&] {
        if (!cur.empty()) tokens.push_back(cur);
        cur.clear();
    };
    for (std::size_t i = 0; i < buf.size(); ++i) {
        const char ch = buf[i];
        if (ch == '/' && i + 1 < buf.size() && buf[i + 1] == '/') {
            flush();
            while (i < buf.size() && buf[i] != '\n') ++i;
        } else if (ch == '/' && i + 1 < buf.size() && buf[i + 1] == '*') {
            flush();
            const auto end = buf.find("*/", i + 2);
            if (end == std::string::npos) break;
            i = end + 1;
        } else if (ch == '"') {
            flush();
            const auto end = buf.find('"', i + 1);
            if (end == std::string::npos) break;
            tokens.push_back(buf.substr(i + 1, end - i - 1));
            i = end;
        } else if (ch == ';' || ch == '{' || ch == '}') {
            flush();
            tokens.emplace_back(1, ch);
        } else if (std::isspace(static_cast<unsigned char>(ch)) || ch == '\0') {
            flush();
        } else {
            cur += ch;
        }
        if (tokens.size() > 2 && tokens.back() == "}") break; // the header's end (checked below)
    }
    flush();
    if (tokens.size() < 2 || tokens[0] != "FoamFile" || tokens[1] != "{") return h;
    h.found = true;
    for (std::size_t i = 2; i + 1 < tokens.size() && tokens[i] != "}"; ++i) {
        if (tokens[i] == "object") h.object = tokens[i + 1];
        else if (tokens[i] == "format") h.format = tokens[i + 1];
        else if (tokens[i] == "class") h.cls = tokens[i + 1];
    }
    return h;
}

std::string readAll(const fs::path& file)
{
    std::ifstream in(file, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

/// Write `text` to `file` (a copy in the shadow case).
void writeFile(const fs::path& file, const std::string& text)
{
    std::ofstream out(file, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw lic::Error("cannot write " + q(file.string()) + " (the OpenFOAM case's temporary shadow)");
}

/// Files OpenFOAM (and VTK) would not take for a field of their own: backups and originals.
bool backupName(const std::string& name)
{
    std::string n = name;
    if (n.size() > 3 && n.compare(n.size() - 3, 3, ".gz") == 0) n.resize(n.size() - 3);
    if (!n.empty() && n.back() == '~') return true;
    for (const char* ext : {".orig", ".bak", ".BAK", ".old", ".save"}) {
        const std::string e(ext);
        if (n.size() > e.size() && n.compare(n.size() - e.size(), e.size(), e) == 0) return true;
    }
    return false;
}

bool isGz(const std::string& name) { return name.size() > 3 && name.compare(name.size() - 3, 3, ".gz") == 0; }

std::string fieldName(const std::string& file) { return isGz(file) ? file.substr(0, file.size() - 3) : file; }

/// `text` (a field file) with its header's `object` set to `name`.
std::string renamedObject(const std::string& text, const std::string& name)
{
    const auto head = text.find("FoamFile");
    const auto close = head == std::string::npos ? head : text.find('}', head);
    if (close == std::string::npos) return text;
    std::size_t pos = head;
    while ((pos = text.find("object", pos)) != std::string::npos && pos < close) {
        const bool wordStart = pos == 0 || std::isspace(static_cast<unsigned char>(text[pos - 1])) || text[pos - 1] == '{'
                               || text[pos - 1] == ';';
        const auto semi = text.find(';', pos);
        if (wordStart && semi != std::string::npos && semi < close)
            return text.substr(0, pos) + "object " + name + text.substr(semi);
        pos += 6;
    }
    return text;
}

/// What a field directory of the read time holds, for the velocity check and the notes.
struct TimeFields
{
    std::vector<std::string> fields;   ///< field names (file names without .gz) linked or copied
    std::vector<std::string> vectors;  ///< those whose header class is a vector field
    std::vector<std::string> leftOut;  ///< "0/U.orig (object U)"
    std::vector<std::string> expanded; ///< "0/U"
};

/// Make `dst` (a new directory of the shadow) the field directory `src` as VTK should read it.
/// `label` names src in notes ("0", "processor1/0.5"); `wanted` is the --grid name (a file picked by
/// name even when its header names another object).
void shadowTimeDir(const fs::path& src, const fs::path& dst, const std::string& label, const std::string& wanted,
                   const FoamDictContext& base, TimeFields& out)
{
    fs::create_directory(dst);
    std::error_code ec;
    std::vector<fs::directory_entry> entries;
    for (const auto& e : fs::directory_iterator(src, ec)) entries.push_back(e);
    std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.path() < b.path(); });
    for (const auto& e : entries) {
        const std::string name = e.path().filename().string();
        const fs::path target = fs::absolute(e.path());
        if (e.is_directory(ec)) { // uniform/, polyMesh/ (a moving mesh), lagrangian/
            fs::create_directory_symlink(target, dst / name);
            continue;
        }
        if (!e.is_regular_file(ec)) continue;
        const std::string field = fieldName(name);
        const bool picked = !wanted.empty() && (name == wanted || field == wanted);
        const FoamHeader h = isGz(name) ? FoamHeader{} : readHeader(e.path());
        if (backupName(name) && !picked) {
            out.leftOut.push_back(label + "/" + name + (h.found ? " (object " + h.object + ")" : ""));
            continue;
        }
        if (isGz(name)) { // VTK reads it; solver output carries no directives
            fs::create_symlink(target, dst / name);
            out.fields.push_back(field);
            continue;
        }
        if (!h.found) { // not a field file: VTK decides
            fs::create_symlink(target, dst / name);
            continue;
        }
        if (h.object != name && !picked) {
            out.leftOut.push_back(label + "/" + name + " (object " + h.object + ")");
            continue;
        }
        out.fields.push_back(field);
        if (h.cls.find("Vector") != std::string::npos) out.vectors.push_back(field);
        if (h.format == "binary") {
            if (h.object != name) { // picked by name: the copy carries its file name as object
                writeFile(dst / name, renamedObject(readAll(e.path()), name));
            } else {
                fs::create_symlink(target, dst / name);
            }
            continue;
        }
        std::string text = readAll(e.path());
        bool copy = h.object != name;
        if (needsFoamExpansion(text, base.patches)) {
            FoamDictContext ctx = base;
            ctx.file = target;
            text = expandFoamDictionary(text, ctx);
            out.expanded.push_back(label + "/" + name);
            copy = true;
        }
        if (!copy) {
            fs::create_symlink(target, dst / name);
            continue;
        }
        if (h.object != name) text = renamedObject(text, name);
        writeFile(dst / name, text);
    }
}

// ---- the shadow case ----------------------------------------------------------------------

/// A temporary directory, removed with everything in it when this goes.
class ShadowDir
{
public:
    ShadowDir()
    {
        static std::atomic<unsigned> counter{0};
        const fs::path base = fs::temp_directory_path();
        for (int attempt = 0; attempt < 100; ++attempt) {
            const fs::path p = base / ("licvdb-foam-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
            std::error_code ec;
            if (fs::create_directory(p, ec)) {
                mPath = p;
                return;
            }
        }
        throw lic::Error("cannot make a temporary directory for an OpenFOAM case under " + q(base.string()));
    }
    ~ShadowDir()
    {
        std::error_code ec;
        fs::remove_all(mPath, ec);
    }
    ShadowDir(const ShadowDir&) = delete;
    ShadowDir& operator=(const ShadowDir&) = delete;
    const fs::path& path() const { return mPath; }

private:
    fs::path mPath;
};

bool hasMesh(const fs::path& polyMesh)
{
    std::error_code ec;
    return fs::exists(polyMesh / "faces", ec) || fs::exists(polyMesh / "faces.gz", ec);
}

/// The directory of `root` (the case, or a processor directory) whose polyMesh the time `timeName`
/// uses: the latest time directory up to it with a polyMesh/faces, else constant. Empty if none.
std::optional<std::string> meshInstance(const fs::path& root, double t)
{
    std::optional<std::string> best;
    double bestT = -HUGE_VAL;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(root, ec)) {
        if (!e.is_directory(ec)) continue;
        const auto v = timeOfName(e.path().filename().string());
        if (v && *v <= t + 1e-9 * std::max(1.0, std::abs(t)) && *v > bestT && hasMesh(e.path() / "polyMesh")) {
            best = e.path().filename().string();
            bestT = *v;
        }
    }
    if (best) return best;
    if (hasMesh(root / "constant" / "polyMesh")) return std::string("constant");
    return std::nullopt;
}

/// Link `root`'s system/ and constant/ into `shadow`, the time directory the mesh comes from if
/// it is a time directory, and make the shadow of the time `timeName`.
void shadowRoot(const fs::path& root, const fs::path& shadow, const std::string& label, const std::string& timeName,
                const std::string& meshDir, const std::string& wanted, const std::vector<fs::path>& etcDirs,
                TimeFields& fields)
{
    std::error_code ec;
    fs::create_directories(shadow);
    for (const char* d : {"system", "constant"})
        if (fs::is_directory(root / d, ec)) fs::create_directory_symlink(fs::absolute(root / d), shadow / d);
    if (meshDir != "constant" && meshDir != timeName) {
        fs::create_directory(shadow / meshDir);
        fs::create_directory_symlink(fs::absolute(root / meshDir / "polyMesh"), shadow / meshDir / "polyMesh");
    }
    FoamDictContext ctx;
    ctx.etcDirs = etcDirs;
    const fs::path boundary = root / meshDir / "polyMesh" / "boundary";
    if (fs::exists(boundary, ec)) ctx.patches = readFoamBoundary(boundary);
    shadowTimeDir(root / timeName, shadow / timeName, (label.empty() ? "" : label + "/") + timeName, wanted, ctx, fields);
}

/// Replace the shadow's path by the case's in `text` (VTK's messages name the files it read).
std::string unshadow(std::string text, const fs::path& shadow, const fs::path& caseDir)
{
    const std::string from = shadow.string(), to = fs::absolute(caseDir).lexically_normal().string();
    for (std::size_t pos = 0; (pos = text.find(from, pos)) != std::string::npos; pos += to.size()) text.replace(pos, from.size(), to);
    return text;
}

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

/// Warn when the velocity read is zero or the same vector everywhere.
void checkNotUniform(vtkDataObject* data, const MeshOptions& options, const std::string& path, double t)
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
        warn("the velocity " + name + " is zero everywhere " + at + " (an initial condition, not a solution?): the "
             "field has no flow to draw");
    else
        warn("the velocity " + name + " is uniform " + at + ", " + vecText(lo) + " in every cell (an initial condition, "
             "not a solution?): its lines are straight and parallel");
}

} // namespace

ReadReportScope::ReadReportScope(ReadReport& report) : mPrevious(tReport) { tReport = &report; }
ReadReportScope::~ReadReportScope() { tReport = mPrevious; }

std::vector<double> openFoamTimes(const std::string& path)
{
    const FoamCase c = scanCase(path);
    std::vector<double> t;
    for (const auto& ft : c.times) t.push_back(ft.value);
    return t;
}

vtkSmartPointer<vtkDataObject> readOpenFoam(const std::string& path, const MeshOptions& options,
                                            std::optional<double>& timeRead, std::vector<double>& times)
{
    const FoamCase c = scanCase(path);
    if (c.times.empty())
        detail::inputError(path, "is an OpenFOAM case without time directories (no 0/ or later"
                                 + std::string(c.processors.empty() ? "" : ", at the top level or in processor*/")
                                 + "): nothing to read");
    times.clear();
    for (const auto& ft : c.times) times.push_back(ft.value);
    if (tReport) {
        tReport->timeSources.clear();
        for (const auto& ft : c.times) tReport->timeSources.push_back(sourceText(c, ft));
    }
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
        if (!tReport || !tReport->describing) detail::inputError(path, what);
        if (!saidNoVelocity) warn(what);
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
    note(readNote);
    std::vector<std::string> leftOut, expanded;
    for (const auto& f : fields) {
        leftOut.insert(leftOut.end(), f.leftOut.begin(), f.leftOut.end());
        expanded.insert(expanded.end(), f.expanded.begin(), f.expanded.end());
    }
    if (!leftOut.empty())
        note("left out " + joinedList(leftOut) + ": backups, or files whose header names another field (the field "
             "named U is the file U; --grid FILE reads one by its file name)");
    if (!expanded.empty()) note("expanded the dictionary directives of " + joinedList(expanded));
    if (times.size() == 1 && times.front() == 0)
        warn("the case has only its initial conditions (0/" + std::string(decomposed ? " in the processor directories" : "")
             + "): no solver has written a time yet; run the solver first (e.g. `simpleFoam`, or `mpirun -np N "
               "<solver> -parallel` for a decomposed case)");
    checkNotUniform(data, options, path, t);
    return data;
}

} // namespace vdbexport::mesh_module

// The shadow case an OpenFOAM read goes through (OpenFoamImpl.h): a temporary directory (removed
// after the read, also on errors) of symlinks to the case's system/ and constant/, and a real
// directory for the time read, at the top level or in every processor*/ directory, holding symlinks
// to its field files except
// (a) files whose header `object` is not their file name (a stale U.orig with `object U;` would
// otherwise replace U: VTK names fields by `object`; "the field named U is the file U"), and
// (b) ASCII files with dictionary directives VTK cannot read (#includeEtc, `uniform $var`,
// boundaryField keyed by patch group), which get expanded copies (FoamDict.h). Gzipped and binary
// field files are linked as they are.
#include "io/mesh/OpenFoamImpl.h"

#include "io/DenseCommon.h"
#include "io/mesh/FoamDict.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>

#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module::openfoam {

using detail::q;

namespace {

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

bool hasMesh(const fs::path& polyMesh)
{
    std::error_code ec;
    return fs::exists(polyMesh / "faces", ec) || fs::exists(polyMesh / "faces.gz", ec);
}

} // namespace

// ---- the shadow case ----------------------------------------------------------------------

ShadowDir::ShadowDir()
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

ShadowDir::~ShadowDir()
{
    std::error_code ec;
    fs::remove_all(mPath, ec);
}

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

std::string unshadow(std::string text, const fs::path& shadow, const fs::path& caseDir)
{
    const std::string from = shadow.string(), to = fs::absolute(caseDir).lexically_normal().string();
    for (std::size_t pos = 0; (pos = text.find(from, pos)) != std::string::npos; pos += to.size()) text.replace(pos, from.size(), to);
    return text;
}

} // namespace vdbexport::mesh_module::openfoam

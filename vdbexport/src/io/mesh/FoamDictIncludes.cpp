// #include and its kin in the OpenFOAM dictionary expander (FoamDictImpl.h): #include,
// #sinclude/#includeIfPresent (optional), #includeEtc/#sincludeEtc searched in OpenFOAM's etc
// directories (foamEtcDirs: user, site, project, then the usual install paths), and the
// <case>/<system>/<constant>/<etc>/~ forms of a file name. A missing
// caseDicts/setConstraintTypes is replaced by its content (foamConstraintTypesDict).
#include "io/mesh/FoamDictImpl.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

namespace foam_dict {

namespace {

constexpr int kMaxIncludeDepth = 16;
constexpr std::size_t kMaxFileBytes = std::size_t(1) << 30;

std::string joinPaths(const std::vector<fs::path>& dirs)
{
    std::string out;
    for (const auto& d : dirs) out += (out.empty() ? "" : ", ") + d.string();
    return out;
}

} // namespace

bool isInclude(const std::string& directive)
{
    return directive == "#include" || directive == "#includeEtc" || directive == "#includeIfPresent" ||
           directive == "#sinclude" || directive == "#sincludeEtc";
}

std::optional<std::string> readWholeFile(const fs::path& path)
{
    std::error_code ec;
    const std::string s = path.lexically_normal().string();
    for (const char* bad : {"/proc/", "/sys/", "/dev/"}) // never block on a device or a kernel file
        if (s.rfind(bad, 0) == 0) return std::nullopt;
    if (!fs::is_regular_file(path, ec)) return std::nullopt;
    const auto size = fs::file_size(path, ec);
    if (ec || size > kMaxFileBytes) return std::nullopt;
    std::ifstream in(path, std::ios::binary);
    if (!in) return std::nullopt;
    std::string text(size, '\0');
    in.read(text.data(), std::streamsize(size));
    text.resize(std::size_t(in.gcount()));
    return text;
}

std::optional<fs::path> Expander::findEtc(const std::string& name) const
{
    std::error_code ec;
    for (const auto& dir : ctx_.etcDirs)
        if (fs::is_regular_file(dir / name, ec)) return dir / name;
    return std::nullopt;
}

fs::path Expander::resolveInclude(const Dict& scope, const Token& directive, const Token& arg)
{
    std::string name = expandString(scope, unquote(arg.text), arg);
    const auto tag = [&](const std::string& t) { return name.rfind(t, 0) == 0; };
    if (tag("<case>")) return caseDir_ / fs::path(name.substr(6)).relative_path();
    if (tag("<system>")) return caseDir_ / "system" / fs::path(name.substr(8)).relative_path();
    if (tag("<constant>")) return caseDir_ / "constant" / fs::path(name.substr(10)).relative_path();
    if (tag("<etc>/") || tag("~OpenFOAM/")) {
        const std::string rest = name.substr(name.find('/') + 1);
        if (auto f = findEtc(rest)) return *f;
        return fs::path(ctx_.etcDirs.empty() ? fs::path("<etc>") : ctx_.etcDirs.front()) / rest;
    }
    if (tag("~/")) {
        const char* home = std::getenv("HOME");
        if (!home) fail(where(directive) + ": " + directive.text + " " + arg.text + ": $HOME is not set");
        return fs::path(home) / name.substr(2);
    }
    fs::path p(name);
    if (p.is_relative() && arg.src && !arg.src->file.empty()) p = arg.src->file.parent_path() / p;
    return p;
}

std::optional<const Source*> Expander::includeSource(const Dict& scope, Lexer& lx, const Token& directive,
                                                     int fileDepth)
{
    const std::string& name = directive.text;
    const Token arg = lx.next();
    if (arg.kind != Tok::String && arg.kind != Tok::Word)
        fail(where(directive) + ": " + name + " expects a file name, found " +
             (arg.kind == Tok::End ? std::string("the end of the file") : dq(arg.text)));
    if (fileDepth >= kMaxIncludeDepth)
        fail(where(directive) + ": " + name + " " + arg.text + ": includes nested more than " +
             std::to_string(kMaxIncludeDepth) + " deep (does a file include itself?)");
    const bool optional = name == "#sinclude" || name == "#includeIfPresent" || name == "#sincludeEtc";
    if (name == "#includeEtc" || name == "#sincludeEtc") {
        const std::string etcName = expandString(scope, unquote(arg.text), arg);
        if (auto f = findEtc(etcName)) {
            if (auto text = readWholeFile(*f)) return &addSource(*f, std::move(*text));
        } else if (fs::path(etcName).lexically_normal() == "caseDicts/setConstraintTypes") {
            return &addSource("<licvdb: caseDicts/setConstraintTypes>", foamConstraintTypesDict());
        }
        if (optional) return std::nullopt;
        fail(where(directive) + ": " + name + " " + arg.text + ": not found in " +
             (ctx_.etcDirs.empty() ? std::string("any OpenFOAM etc directory (none found: set WM_PROJECT_DIR "
                                                 "or install OpenFOAM)")
                                   : joinPaths(ctx_.etcDirs)));
    }
    const fs::path file = resolveInclude(scope, directive, arg);
    if (auto text = readWholeFile(file)) return &addSource(file, std::move(*text));
    if (optional) return std::nullopt;
    fail(where(directive) + ": " + name + " " + arg.text + ": cannot open " + file.string());
}

} // namespace foam_dict

std::vector<fs::path> foamEtcDirs()
{
    std::vector<fs::path> dirs;
    std::error_code ec;
    const auto add = [&](const fs::path& p) {
        if (!p.empty() && fs::is_directory(p, ec) && std::find(dirs.begin(), dirs.end(), p) == dirs.end())
            dirs.push_back(p);
    };
    const auto newestFirst = [&](const fs::path& parent, const std::string& prefix, const fs::path& sub) {
        std::vector<fs::path> found;
        for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec))
            if (it->path().filename().string().rfind(prefix, 0) == 0) found.push_back(it->path() / sub);
        std::sort(found.rbegin(), found.rend());
        for (const auto& f : found) add(f);
    };
    if (const char* home = std::getenv("HOME"); home && *home) {
        const fs::path user = fs::path(home) / ".OpenFOAM";
        if (const char* api = std::getenv("WM_PROJECT_VERSION"); api && *api) add(user / api);
        add(user);
    }
    if (const char* site = std::getenv("WM_PROJECT_SITE"); site && *site) add(fs::path(site) / "etc");
    if (const char* dir = std::getenv("WM_PROJECT_DIR"); dir && *dir) add(fs::path(dir) / "etc");
    add("/usr/share/openfoam/etc");
    newestFirst("/usr/lib/openfoam", "openfoam", "etc");
    newestFirst("/opt", "openfoam", "etc");
    newestFirst("/opt", "OpenFOAM", "etc");
    return dirs;
}

} // namespace vdbexport::mesh_module

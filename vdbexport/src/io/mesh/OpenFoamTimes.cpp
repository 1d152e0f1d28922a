// An OpenFOAM case's layout and times (OpenFoamImpl.h): its case directory (from the directory, a
// `case.foam` or the controlDict), its processor*/ directories, and its times, those of the top
// level and of the processor directories. A time is in the processors when every one has it; it is
// read from them when they have it, else from the top level; a time only some processors have is
// incomplete (reading it is an error naming them: nothing falls back silently).
#include "io/mesh/Mesh.h"
#include "io/mesh/OpenFoamImpl.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace openfoam {

namespace {

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

} // namespace

std::string joinedList(const std::vector<std::string>& items, const std::string& sep, std::size_t most)
{
    std::string s;
    for (std::size_t i = 0; i < items.size() && i < most; ++i) s += (i ? sep : "") + items[i];
    if (items.size() > most) s += sep + "… (" + std::to_string(items.size()) + " in all)";
    return s;
}

std::optional<double> timeOfName(const std::string& name)
{
    if (name.empty() || name.find_first_of("xXnN") != std::string::npos || name[0] == '+') return std::nullopt;
    char* end = nullptr;
    const double v = std::strtod(name.c_str(), &end);
    if (end != name.c_str() + name.size() || !std::isfinite(v)) return std::nullopt;
    return v;
}

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

} // namespace openfoam

std::vector<double> openFoamTimes(const std::string& path)
{
    const openfoam::FoamCase c = openfoam::scanCase(path);
    std::vector<double> t;
    for (const auto& ft : c.times) t.push_back(ft.value);
    return t;
}

} // namespace vdbexport::mesh_module

// Loading licvdb's run-time modules (Module.h).
#include "Module.h"

#include "DenseCommon.h"
#include "vdbexport/io/Program.h"

#include <filesystem>
#include <map>
#include <mutex>
#include <vector>

#include <dlfcn.h>

namespace fs = std::filesystem;

namespace vdbexport::module {

namespace {

std::vector<fs::path> candidates(const Spec& spec)
{
    if (const char* env = std::getenv(spec.envVar); env && *env) return {env};
    std::vector<fs::path> out;
    const fs::path exe = program::path();
    if (!exe.empty()) {
        out.push_back(exe.parent_path() / spec.id.fileName);
        out.push_back(exe.parent_path() / ".." / "libexec" / "licvdb" / spec.id.fileName);
    }
    for (const char* p : {spec.buildPath, spec.installedPath})
        if (p && *p) out.emplace_back(p);
    return out;
}

/// The first candidate that exists, opened, its table returned; or why not in `failure`.
const void* open(const Spec& spec, std::string& failure)
{
    const std::string name = std::string("licvdb's ") + spec.name;
    std::string tried;
    for (const fs::path& p : candidates(spec)) {
        const std::string shown = detail::q(p.lexically_normal().string());
        std::error_code ec;
        if (!fs::is_regular_file(p, ec)) {
            tried += (tried.empty() ? "" : ", ") + p.lexically_normal().string();
            continue;
        }
        void* handle = ::dlopen(p.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) {
            const char* why = ::dlerror();
            failure = name + " " + shown + " cannot be loaded (" + (why ? why : "no reason given")
                      + "); reinstall licvdb";
            return nullptr;
        }
        using Entry = const void* (*)();
        const auto entry = reinterpret_cast<Entry>(::dlsym(handle, spec.id.entry));
        const void* table = entry ? entry() : nullptr;
        if (!table || *static_cast<const int*>(table) != spec.id.version) {
            failure = name + " " + shown + " is not the one this licvdb was built with; reinstall licvdb";
            return nullptr;
        }
        return table;
    }
    failure = name + " (" + spec.id.fileName + ": " + spec.contents + ") is missing; looked for " + tried
              + "; reinstall licvdb or set $" + spec.envVar;
    return nullptr;
}

} // namespace

const void* load(const Spec& spec)
{
    struct Loaded
    {
        const void* table = nullptr;
        std::string failure;
    };
    static std::mutex mutex;
    static std::map<std::string, Loaded> loaded; // by file name: each module opened once
    std::lock_guard lock(mutex);
    auto [it, fresh] = loaded.try_emplace(spec.id.fileName);
    if (fresh) it->second.table = open(spec, it->second.failure);
    if (!it->second.table) throw lic::Error(it->second.failure);
    return it->second.table;
}

} // namespace vdbexport::module

// Where the running licvdb is (Program.h).
#include "vdbexport/io/Program.h"

#include <cstdlib>
#include <filesystem>
#include <system_error>

#include <unistd.h>

namespace fs = std::filesystem;

namespace vdbexport::program {

namespace {

struct Where
{
    std::string program, restart;
    bool bundle = false;
};

/// A dynamic loader's file name (ld-linux-x86-64.so.2, ld-linux.so.2, ld.so, ld-2.36.so …).
bool isLoader(const fs::path& p)
{
    const std::string name = p.filename().string();
    return name.rfind("ld-linux", 0) == 0 || name.rfind("ld.so", 0) == 0 || name.rfind("ld-2.", 0) == 0;
}

Where find()
{
    Where w;
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (ec) return w;
    const char* bundle = std::getenv("LICVDB_BUNDLE");
    if (isLoader(exe) && bundle && *bundle) {
        // Started by the bundle's launcher through its loader: the program and the launcher are
        // in the bundle (set by bin/licvdb, never trusted when the kernel started the program).
        const fs::path root = fs::weakly_canonical(bundle, ec);
        const fs::path program = root / "libexec" / "licvdb" / "licvdb", launcher = root / "bin" / "licvdb";
        if (!ec && fs::is_regular_file(program, ec) && ::access(launcher.c_str(), X_OK) == 0) {
            w.program = program.string();
            w.restart = launcher.string();
            w.bundle = true;
        }
        return w;
    }
    if (isLoader(exe)) return w; // run through a loader by hand: nothing known to start again
    w.program = w.restart = exe.string();
    return w;
}

const Where& where()
{
    static const Where w = find();
    return w;
}

} // namespace

std::string path() { return where().program; }
std::string restartPath() { return where().restart; }
bool inBundle() { return where().bundle; }

} // namespace vdbexport::program

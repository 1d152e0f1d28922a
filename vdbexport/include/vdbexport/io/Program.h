// Where the running licvdb is, and how to start it again.
//
// A build or an installed licvdb is started by the kernel: /proc/self/exe is the program. The
// relocatable bundle (scripts/bundle) starts it through the dynamic loader it carries,
// `lib/ld-linux-x86-64.so.2 --inhibit-cache --library-path lib libexec/licvdb/licvdb …`, from
// its launcher `bin/licvdb`, which also sets $LICVDB_BUNDLE to the bundle's folder: there
// /proc/self/exe is the loader, and starting it again would start the loader alone. Everything
// that looks for licvdb's own files (modules, the OCIO config) or starts licvdb again (read
// isolation, mesh reads) asks here instead of reading /proc/self/exe.
#pragma once

#include <string>

namespace vdbexport::program {

/// The running licvdb program file (the ELF, never the loader); "" if it cannot be found.
/// Modules and resources are found relative to it (`../share/licvdb`, `libexec/licvdb/`).
std::string path();

/// What to execute to run licvdb again with the same libraries: the bundle's launcher
/// (`bin/licvdb`) when this licvdb runs from a bundle, else path(). "" if unknown.
std::string restartPath();

/// True when this licvdb runs from a relocatable bundle (through its own loader).
bool inBundle();

} // namespace vdbexport::program

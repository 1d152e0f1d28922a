// What licvdb's run-time modules share: licvdb-image.so (OpenImageIO, OpenColorIO) and
// licvdb-mesh.so (VTK). Each holds libraries that cost every licvdb start their relocations
// (OpenImageIO's ~260 shared libraries ~0.3 s of CPU, VTK's 39 ~0.05 s) and that only some
// commands need, so licvdb loads a module on first use (dlopen) and calls it through a table of
// functions. Modules are built with licvdb by the same compiler: tables pass C++ types. Errors do
// not cross the boundary as exceptions: each entry returns a Status, which check() turns back into
// the exception the entry threw.
#pragma once

#include <lic/util/Error.h>

#include <exception>
#include <string>

namespace vdbexport::module {

/// What an entry reports: ok, a runtime failure (lic::Error), bad input (lic::InputError) or a
/// cancellation (lic::Cancelled).
struct Status
{
    enum Kind { Ok = 0, Failure = 1, Input = 2, Cancelled = 3 };
    int kind = Ok;
    std::string message;
};

/// In a module: runs `body`, reporting its exceptions as a Status (none crosses into licvdb).
template <typename F>
Status guarded(F&& body, const char* where)
{
    try {
        body();
        return {};
    } catch (const lic::Cancelled& e) {
        return {Status::Cancelled, e.what()};
    } catch (const lic::InputError& e) {
        return {Status::Input, e.what()};
    } catch (const std::exception& e) {
        return {Status::Failure, e.what()};
    } catch (...) {
        return {Status::Failure, std::string("unknown error in ") + where};
    }
}

/// In licvdb: throws what the entry reported (nothing for Ok).
inline void check(const Status& s)
{
    if (s.kind == Status::Input) throw lic::InputError(s.message);
    if (s.kind == Status::Cancelled) throw lic::Cancelled();
    if (s.kind != Status::Ok) throw lic::Error(s.message);
}

/// Which module a file is: its name, the extern "C" function that returns its table, and the
/// table's version (its first member, `int version`; bumped whenever the table changes, and the
/// loader refuses a module of another version).
struct Identity
{
    const char* fileName; ///< e.g. "licvdb-mesh.so"
    const char* entry;    ///< e.g. "licvdb_mesh_module"
    int version;
};

/// Where a module is and what it is called.
struct Spec
{
    const char* name;          ///< for messages: "image module", "mesh module"
    Identity id;
    const char* envVar;        ///< an environment variable that names the file instead
    const char* buildPath;     ///< where this build put it ("" if unknown)
    const char* installedPath; ///< where `cmake --install` puts it ("" if unknown)
    const char* contents;      ///< for messages: what it holds, e.g. "OpenImageIO, OpenColorIO"
};

/// @brief Loads the module (once per process; never unloaded) and returns its table, whose first
///        member must be `int version` equal to spec.id.version. Looks at $envVar alone if set;
///        else beside the running program, in its ../libexec/licvdb/, at buildPath, at installedPath.
/// @throw lic::Error naming where it looked, or why the file found could not be used.
const void* load(const Spec& spec);

} // namespace vdbexport::module

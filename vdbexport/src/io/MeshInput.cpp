// Mesh input (MeshInput.h) through licvdb's mesh module, licvdb-mesh.so (MeshModuleApi.h), loaded
// on first use: VTK's libraries are mapped only by the commands that read a mesh.
#include "vdbexport/io/MeshInput.h"
#include "vdbexport/io/VdbCheck.h"

#include "MeshModuleApi.h"

#include <sstream>

namespace vdbexport {

namespace {

const mesh_module::Api& meshModule()
{
    static const module::Spec spec{"mesh module", mesh_module::kModule, kMeshModuleEnv,
                                   LICVDB_MESH_MODULE_BUILD, LICVDB_MESH_MODULE_INSTALLED, "VTK's mesh readers"};
    return *static_cast<const mesh_module::Api*>(module::load(spec));
}

/// A number exactly (17 significant digits), for a child's command line.
std::string num17(double v)
{
    std::ostringstream o;
    o.precision(17);
    o << v;
    return o.str();
}

/// VTK's readers are not hardened against malformed files (VTK 9.1's XML reader dereferences null
/// on a bad ASCII number: found by fuzz_vtu): `licvdb` first reads the mesh in a child process
/// (`licvdb convert PATH --list`, as .vdb files are read, see VdbCheck.h), so a file that crashes
/// or hangs VTK is refused without taking the program down. Nothing happens in library use or in
/// the child itself (no executable set).
void readInChildFirst(const std::string& path, const std::string& format, const MeshOptions& options)
{
    if (readIsolationExecutable().empty()) return;
    std::vector<std::string> args{"convert", "--list", "--quiet", "--format", format};
    if (options.time) args.insert(args.end(), {"--time", num17(*options.time)});
    if (!options.solution.empty()) args.insert(args.end(), {"--solution", options.solution});
    args.insert(args.end(), {"--", path});
    checkReadInIsolatedProcess(path, args, "VTK's reader", meshModule().describeFormat(format));
}

} // namespace

bool meshInputAvailable() { return true; }

std::vector<double> meshTimes(const std::string& path, const std::string& format)
{
    std::vector<double> times;
    module::check(meshModule().meshTimes(path, format, times));
    return times;
}

MeshSummary describeMesh(const std::string& path, const std::string& format, const MeshOptions& options)
{
    readInChildFirst(path, format, options);
    MeshSummary summary;
    module::check(meshModule().describeMesh(path, format, options, summary));
    return summary;
}

LoadedField loadMesh(const std::string& path, const std::string& format, const MeshOptions& options,
                     const std::string& nanPolicy)
{
    readInChildFirst(path, format, options);
    LoadedField field;
    module::check(meshModule().loadMesh(path, format, options, nanPolicy, field));
    return field;
}

} // namespace vdbexport

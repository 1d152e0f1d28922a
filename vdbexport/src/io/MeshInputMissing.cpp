// Mesh input when licvdb is built without VTK (LICVDB_VTK=OFF): every mesh format is refused
// with what to install.
#include "vdbexport/io/MeshInput.h"

#include <lic/util/Error.h>

#include <set>

namespace vdbexport {

namespace {

[[noreturn]] void missing(const std::string& path)
{
    throw lic::InputError("'" + path + "' is a mesh (VTK, PLOT3D or OpenFOAM), and this licvdb was built without VTK: "
                          "install libvtk9-dev (scripts/install-deps) and rebuild, or resample the mesh to a .vti or .vdb first");
}

} // namespace

bool meshInputAvailable() { return false; }


std::vector<double> meshTimes(const std::string& path, const std::string&) { missing(path); }

MeshSummary describeMesh(const std::string& path, const std::string&, const MeshOptions&) { missing(path); }

LoadedField loadMesh(const std::string& path, const std::string&, const MeshOptions&, const std::string&) { missing(path); }

} // namespace vdbexport

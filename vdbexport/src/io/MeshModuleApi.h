// The mesh module's interface: what licvdb-mesh.so (MeshModule.cpp: VTK's readers and probe) gives
// the loader in MeshInput.cpp, which implements MeshInput.h. VTK's 39 shared libraries cost every
// licvdb start ~0.05 s of relocations; only mesh input needs them, so they are loaded on first
// use (Module.h).
#pragma once

#include "Module.h"
#include "vdbexport/io/MeshInput.h"

#include <string>
#include <vector>

namespace vdbexport::mesh_module {

inline constexpr module::Identity kModule{"licvdb-mesh.so", "licvdb_mesh_module", /*version=*/3};

using module::Status;

/// The table (kModule.version is bumped whenever it changes).
struct Api
{
    int version;
    /// See vdbexport::meshTimes.
    Status (*meshTimes)(const std::string& path, const std::string& format, std::vector<double>& times);
    /// See vdbexport::describeMesh (without the read in a child process first).
    Status (*describeMesh)(const std::string& path, const std::string& format, const MeshOptions& options,
                           MeshSummary& summary);
    /// See vdbexport::loadMesh (without the read in a child process first).
    Status (*loadMesh)(const std::string& path, const std::string& format, const MeshOptions& options,
                       const std::string& nanPolicy, LoadedField& field);
    /// "a VTK XML unstructured grid (.vtu)" for "vtu", and so on: for messages.
    std::string (*describeFormat)(const std::string& format);
};

// The module's own functions (MeshModule.cpp), behind the table; the fuzz target calls them directly.
std::vector<double> meshTimes(const std::string& path, const std::string& format);
MeshSummary describeMesh(const std::string& path, const std::string& format, const MeshOptions& options);
LoadedField loadMesh(const std::string& path, const std::string& format, const MeshOptions& options,
                     const std::string& nanPolicy);

} // namespace vdbexport::mesh_module

extern "C" const vdbexport::mesh_module::Api* licvdb_mesh_module();

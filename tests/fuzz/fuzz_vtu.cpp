// libFuzzer target: the mesh path (vdbexport/io/MeshInput.h) on arbitrary bytes as a .vtu file:
// VTK's XML reader parses it, then licvdb's checks and VTK's resampling run on what it read.
// Any exception other than lic::InputError, any crash or sanitizer report is a finding.
#include "vdbexport/io/MeshInput.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    // VTK's readers read files: one per fuzzing process, rewritten for each input.
    static const std::string path =
        (std::filesystem::temp_directory_path() / ("licvdb_fuzz_" + std::to_string(::getpid()) + ".vtu")).string();
    {
        std::ofstream out(path, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    }
    vdbexport::MeshOptions options;
    options.maxVoxels = 200000; // keep each input's lattice small
    try {
        vdbexport::loadMesh(path, "vtu", options, "zero");
    } catch (const lic::InputError&) {
    }
    try {
        vdbexport::loadMesh(path, "vtu", options, "refuse");
    } catch (const lic::InputError&) {
    }
    return 0;
}

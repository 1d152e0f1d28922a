// libFuzzer target: the mesh path (the mesh module's loadMesh, io/MeshModuleApi.h: what
// vdbexport/io/MeshInput.h runs after its read in a child process) on arbitrary bytes as a .vtu file:
// VTK's XML reader parses it, then licvdb's checks and VTK's resampling run on what it read.
// Any exception other than lic::InputError, any crash or sanitizer report is a finding.
//
// VTK 9.1's XML reader itself dereferences null on some malformed files (this target found one in
// 14 runs: a bad ASCII number in a cell array). licvdb reads meshes in a child process first for
// that reason (MeshInput.cpp readInChildFirst), so here too each input is first parsed by VTK in a
// forked child: a child killed by a signal or a time limit is what licvdb refuses as a corrupt
// file, and only inputs VTK survives go on, in this process, through the whole path (whose
// coverage guides the fuzzer).
#include "io/MeshModuleApi.h"

#include <lic/util/Error.h>

#include <vtkLogger.h>
#include <vtkNew.h>
#include <vtkOutputWindow.h>
#include <vtkXMLUnstructuredGridReader.h>

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

namespace {

/// True if VTK's reader (alone: none of licvdb's code runs in the child, so nothing of ours is
/// hidden there) reads `path` in a child process without a crash or a hang.
bool vtkSurvives(const std::string& path)
{
    const pid_t pid = ::fork();
    if (pid < 0) return false;
    if (pid == 0) {
        // The default actions: a crash kills the child quietly (no report, no artifact: it is the
        // expected outcome that licvdb turns into a refusal).
        for (int sig : {SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL}) std::signal(sig, SIG_DFL);
        ::alarm(5);
        vtkOutputWindow::GetInstance()->SetDisplayModeToNever();
        vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);
        vtkNew<vtkXMLUnstructuredGridReader> reader;
        reader->SetFileName(path.c_str());
        reader->Update();
        ::_exit(0);
    }
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0) {}
    return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

} // namespace

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
    if (!vtkSurvives(path)) return 0;
    for (const char* nanPolicy : {"refuse", "zero"}) {
        try {
            vdbexport::mesh_module::loadMesh(path, "vtu", options, nanPolicy);
        } catch (const lic::InputError&) {
        }
    }
    return 0;
}

// libFuzzer target: OpenFOAM dictionary expansion (vdbexport/src/io/mesh/FoamDict.cpp) on arbitrary
// text as a case's 0/U, with a few include files, an etc directory and a patch list around it; and
// the same text as a constant/polyMesh/boundary file. An expansion must expand again to the same
// entries (it is a fixed point: nothing left to expand, one entry per patch).
// Any exception other than lic::InputError, any crash, hang or sanitizer report is a finding.
#include "io/mesh/FoamDict.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

namespace fs = std::filesystem;
using namespace vdbexport::mesh_module;

namespace {

struct Fixture
{
    fs::path root, boundary;
    FoamDictContext withPatches, plain;

    Fixture()
    {
        // The environment is a fallback for $name: keep it small and plain, so that the inputs
        // decide what is expanded.
        ::clearenv();
        ::setenv("HOME", "/nonexistent", 1);
        ::setenv("FLOW", "(1 2 3)", 1);
        root = fs::temp_directory_path() / ("fuzz_foam_dict_" + std::to_string(::getpid()));
        fs::create_directories(root / "case" / "0" / "include");
        fs::create_directories(root / "case" / "constant" / "polyMesh");
        fs::create_directories(root / "etc" / "caseDicts");
        std::ofstream(root / "case" / "0" / "include" / "initialConditions")
            << "flowVelocity (20 0 0);\npressure 0;\nturbulentKE 0.24;\n";
        std::ofstream(root / "case" / "0" / "include" / "fixedInlet")
            << "inlet\n{\n    type fixedValue;\n    value $internalField;\n}\n";
        std::ofstream(root / "case" / "0" / "include" / "self") << "#include \"self\"\n";
        std::ofstream(root / "case" / "0" / "vel") << "uniform (3 0 0)\n";
        std::ofstream(root / "etc" / "caseDicts" / "other") << "extra { type slip; }\n";
        boundary = root / "case" / "constant" / "polyMesh" / "boundary";
        withPatches.file = root / "case" / "0" / "U";
        withPatches.etcDirs = {root / "etc"}; // no setConstraintTypes there: the synthesised one
        withPatches.patches = {{"inlet", "patch", {}},
                               {"outlet", "patch", {}},
                               {"walls", "wall", {"wall"}},
                               {"side1", "cyclicAMI", {"cyclicAMI"}},
                               {"procBoundary0to1", "processor", {"processor"}},
                               {"frontAndBack", "empty", {"empty"}}};
        plain = withPatches;
        plain.patches.clear();
    }
    ~Fixture() { fs::remove_all(root); }
};

void expandTwice(const std::string& text, const FoamDictContext& ctx)
{
    std::string once;
    try {
        once = expandFoamDictionary(text, ctx);
    } catch (const lic::InputError&) {
        return;
    }
    // What expanded once expands again, to the same entries.
    if (foamDictionaryEntries(once, ctx) != foamDictionaryEntries(expandFoamDictionary(once, ctx), ctx)) std::abort();
    if (!ctx.patches.empty() && needsFoamExpansion(once, ctx.patches) &&
        once.find("#{") == std::string::npos) // a #{ #} block keeps its text: not judged
        std::abort();
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    static Fixture fx;
    const std::string text(reinterpret_cast<const char*>(data), size);
    needsFoamExpansion(text);
    needsFoamExpansion(text, fx.withPatches.patches);
    expandTwice(text, fx.plain);
    expandTwice(text, fx.withPatches);
    std::ofstream(fx.boundary, std::ios::binary | std::ios::trunc) << text;
    try {
        readFoamBoundary(fx.boundary);
    } catch (const lic::InputError&) {
    }
    return 0;
}

// The set-up the bake suites share: a scratch directory of the suite's own under the system's
// temporary directory, made before its first test and removed after its last, and analytic preset
// fields written into it as .vdb files.
#pragma once

#include "vdbexport/io/AtomicWrite.h"

#include <lic/field/Presets.h>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <filesystem>
#include <string>
#include <system_error>

#include <unistd.h>

namespace lictest {

/// `<temporary directory>/licvdb_<name>_<pid>`: a directory of this test process alone.
inline std::filesystem::path processTempDir(const std::string& name)
{
    return std::filesystem::temp_directory_path() / ("licvdb_" + name + "_" + std::to_string(::getpid()));
}

/// What writePresetField writes: the velocity grid alone, or with the preset's scalar grids.
enum class PresetGrids { Velocity, WithScalars };

/// Write preset `preset` (lic/field/Presets.h) at `res` voxels and time `time` to the .vdb file
/// `path`; returns the field, for tests that also use its grids.
inline lic::PresetField writePresetField(const std::filesystem::path& path, const std::string& preset,
                                         const openvdb::Coord& res, PresetGrids grids = PresetGrids::WithScalars,
                                         double time = 0.0)
{
    lic::PresetField f = lic::makePresetField(preset, res, time);
    openvdb::GridPtrVec out{f.velocity};
    if (grids == PresetGrids::WithScalars)
        for (const auto& s : f.scalars) out.push_back(s);
    vdbexport::writeVdbAtomic(path.string(), out);
    return f;
}

/// A suite with a scratch directory `sDir` (one per Suite: Suite derives from TempDirSuite<Suite>).
/// The suite's SetUpTestSuite calls makeSuiteDir(name) first, then writes its inputs there;
/// TearDownTestSuite removes the directory and everything in it.
template <class Suite>
class TempDirSuite : public ::testing::Test
{
protected:
    /// Initialize OpenVDB and make sDir = processTempDir(name) afresh, with the subdirectory
    /// `sub` if given (e.g. "logs").
    static void makeSuiteDir(const std::string& name, const std::string& sub = "")
    {
        openvdb::initialize();
        sDir = processTempDir(name);
        std::filesystem::remove_all(sDir);
        std::filesystem::create_directories(sub.empty() ? sDir : sDir / sub);
    }
    static void TearDownTestSuite()
    {
        std::error_code ec;
        std::filesystem::remove_all(sDir, ec);
    }

    /// sDir/<the current test's name>, made if missing: a test's own outputs.
    static std::filesystem::path testDir()
    {
        const std::filesystem::path d = sDir / ::testing::UnitTest::GetInstance()->current_test_info()->name();
        std::filesystem::create_directories(d);
        return d;
    }

    static inline std::filesystem::path sDir;
};

} // namespace lictest

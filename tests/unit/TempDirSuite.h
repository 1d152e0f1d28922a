// The set-up the test suites share: a scratch directory of the suite's own under the system's
// temporary directory, made before its first test and removed after its last (TempDirSuite), or one
// of each test's own, made before it and removed after it (TempDirTest); and analytic preset fields
// written into it as .vdb files.
#pragma once

#include "vdbexport/io/AtomicWrite.h"

#include <lic/field/Presets.h>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>

#include <atomic>
#include <cctype>
#include <filesystem>
#include <iostream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

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

/// A test with a scratch directory of its own, `mDir`. SetUp initializes OpenVDB and makes mDir =
/// processTempDir("<suite>_<test>_<n>") afresh and empty but for the subdirectories named to the
/// constructor (e.g. {"work", "logs"}); n counts the process's tests, so a --gtest_repeat run gets
/// new ones, and characters other than letters and digits become '_'. TearDown removes it after a
/// passing test and keeps it, naming it on stderr, after a failing one. A fixture whose SetUp does
/// more calls TempDirTest::SetUp() first.
class TempDirTest : public ::testing::Test
{
protected:
    explicit TempDirTest(std::vector<std::string> subdirs = {}) : mSubdirs(std::move(subdirs)) {}

    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        std::string name = std::string(info->test_suite_name()) + "_" + info->name() + "_" + std::to_string(counter++);
        for (char& c : name)
            if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
        mDir = processTempDir(name);
        std::filesystem::remove_all(mDir);
        std::filesystem::create_directories(mDir);
        for (const auto& sub : mSubdirs) std::filesystem::create_directories(mDir / sub);
    }
    void TearDown() override
    {
        std::error_code ec;
        if (!HasFailure()) std::filesystem::remove_all(mDir, ec);
        else std::cerr << "kept test directory " << mDir << "\n";
    }

    std::filesystem::path mDir;

private:
    std::vector<std::string> mSubdirs;
};

} // namespace lictest

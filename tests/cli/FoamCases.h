// The real OpenFOAM cases the tests read (test_openfoam, test_foam_dict): made from Debian's
// OpenFOAM v1912 tutorials by tests/openfoam/make_cases.sh into a cache ($LICVDB_FOAM_CACHE,
// default /var/cache/licvdb/openfoam). The script locks the cache and skips the cases it made
// already, so any test process may run it. Without OpenFOAM (the script exits 77) a test that
// needs the cases fails with kNotRun, unless LICVDB_ALLOW_NO_OPENFOAM=1 makes it skip.
#pragma once

#include "CliRun.h"

#include <cstdlib>
#include <filesystem>
#include <string>

#include <unistd.h>

namespace foam_test {

namespace fs = std::filesystem;

inline constexpr const char* kNotRun = "NOT RUN: OpenFOAM not installed (apt-get install openfoam openfoam-examples)";
inline constexpr const char* kAllowNoOpenFoam = " (set LICVDB_ALLOW_NO_OPENFOAM=1 to skip instead)";

inline fs::path foamCache()
{
    const char* env = std::getenv("LICVDB_FOAM_CACHE");
    return env && *env ? fs::path(env) : fs::path("/var/cache/licvdb/openfoam");
}

/// LICVDB_ALLOW_NO_OPENFOAM=1: tests that need OpenFOAM skip without it instead of failing.
inline bool allowNoOpenFoam()
{
    const char* allow = std::getenv("LICVDB_ALLOW_NO_OPENFOAM");
    return allow && std::string(allow) == "1";
}

/// OpenFOAM is missing: skip with `why` (anything `<<` takes) if LICVDB_ALLOW_NO_OPENFOAM=1, else
/// fail with it and the hint. Returns from the test.
#define FOAM_TEST_NOT_RUN(why)                                                                    \
    do {                                                                                          \
        if (::foam_test::allowNoOpenFoam()) GTEST_SKIP() << why;                                  \
        FAIL() << why << ::foam_test::kAllowNoOpenFoam;                                           \
    } while (0)

/// make_cases.sh's exit status (77: OpenFOAM not installed) and output.
struct Cases
{
    int code = -1;
    std::string log;
};

/// make_cases.sh run on foamCache(), once per test process.
inline const Cases& cases()
{
    static const Cases c = [] {
        using cli_test::shellQuote;
        Cases r;
        const fs::path log = fs::temp_directory_path() / ("licvdb_make_cases_" + std::to_string(::getpid()) + ".log");
        const std::string cmd = "bash " + shellQuote(std::string(LICVDB_SOURCE_DIR) + "/tests/openfoam/make_cases.sh") + " "
                                + shellQuote(foamCache().string()) + " >" + shellQuote(log.string()) + " 2>&1";
        const int status = std::system(cmd.c_str());
        r.code = status == -1 ? -1 : WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        r.log = cli_test::readText(log);
        std::error_code ec;
        fs::remove(log, ec);
        return r;
    }();
    return c;
}

} // namespace foam_test

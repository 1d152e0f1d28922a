// A small harness for the input-format CLI tests (test_bad_input, test_inputs): each test runs
// the built `licvdb` (LICVDB_EXE) in its own temporary directory and captures stdout, stderr
// and the exit status; helpers write .npy / .vti fixtures byte by byte.
#pragma once

#include "CliRun.h"
#include "../unit/TempDirSuite.h"

#include <gtest/gtest.h>

#include <openvdb/openvdb.h>

#include <cctype>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace inputs_test {

namespace fs = std::filesystem;

using cli_test::lower;
using cli_test::readText;
using cli_test::RunResult;
using cli_test::shellQuote;

inline void writeBytes(const fs::path& p, const std::string& bytes)
{
    std::ofstream out(p, std::ios::binary);
    out << bytes;
}

template<typename T>
void append(std::string& s, T v)
{
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    s.append(b, sizeof(T));
}

/// A .npy v1.0 file (little-endian float32 unless `descr` says otherwise).
inline std::string npy(const std::string& descr, const std::string& shape, const std::string& data, bool fortran = false)
{
    std::string dict = "{'descr': '" + descr + "', 'fortran_order': " + (fortran ? "True" : "False") + ", 'shape': " + shape + ", }";
    while ((10 + dict.size() + 1) % 64 != 0) dict += ' ';
    dict += '\n';
    std::string s("\x93NUMPY\x01\x00", 8);
    append<uint16_t>(s, uint16_t(dict.size()));
    return s + dict + data;
}

/// float32 data of shape (X,Y,Z,3), C order, from f(i,j,k).
inline std::string npyData(int X, int Y, int Z, const std::function<openvdb::Vec3s(int, int, int)>& f)
{
    std::string d;
    for (int i = 0; i < X; ++i)
        for (int j = 0; j < Y; ++j)
            for (int k = 0; k < Z; ++k) {
                const openvdb::Vec3s v = f(i, j, k);
                for (int c = 0; c < 3; ++c) append<float>(d, v[c]);
            }
    return d;
}

/// A solid-body rotation about z (plus a small upward drift): a field with lines everywhere.
inline openvdb::Vec3s swirl(int i, int j, int, int X, int Y)
{
    const float x = float(i) - 0.5f * float(X - 1), y = float(j) - 0.5f * float(Y - 1);
    return openvdb::Vec3s(-y, x, 0.3f);
}

class InputsTest : public lictest::TempDirTest
{
protected:
    InputsTest() : TempDirTest({"work", "logs"}) {}

    fs::path work(const std::string& name = "") const { return name.empty() ? mDir / "work" : mDir / "work" / name; }

    RunResult runCommand(const std::string& command) { return cli_test::runShell(work(), mDir / "logs", command); }

    RunResult run(const std::vector<std::string>& args) { return runCommand(cli_test::licvdbCommand(args)); }

    /// Run licvdb with `args` in the work directory and expect a refusal: exit 2, each of `words`
    /// in stderr (case-insensitive), no crash, and no file or directory created.
    RunResult expectRefusedWritingNothing(const std::vector<std::string>& args, const std::vector<std::string>& words)
    {
        const fs::path w = work();
        std::set<std::string> before;
        for (const auto& e : fs::recursive_directory_iterator(w)) before.insert(e.path().string());
        const RunResult r = run(args);
        EXPECT_EQ(r.code, 2) << r.describe();
        const std::string err = lower(r.err);
        for (const auto& word : words)
            EXPECT_NE(err.find(lower(word)), std::string::npos) << "stderr lacks \"" << word << "\"\n" << r.describe();
        EXPECT_EQ(err.find("terminate"), std::string::npos) << r.describe();
        std::vector<std::string> created;
        for (const auto& e : fs::recursive_directory_iterator(w))
            if (!before.count(e.path().string())) created.push_back(e.path().string());
        EXPECT_TRUE(created.empty()) << "created: " << (created.empty() ? "" : created.front()) << "\n" << r.describe();
        return r;
    }

public:
    /// Bake arguments with small, fast defaults (--length 4 --step 0.5 --upsample 1); `extra` is appended.
    static std::vector<std::string> bakeArgs(const fs::path& field, const fs::path& out, std::vector<std::string> extra = {})
    {
        std::vector<std::string> a{"bake", "--field", field.string(), "--out", out.string()};
        // Defaults that `extra` does not set itself (CLI11 rejects a flag given twice).
        for (const auto& [flag, value] : std::vector<std::pair<std::string, std::string>>{
                 {"--length", "4"}, {"--step", "0.5"}, {"--upsample", "1"}}) {
            bool given = false;
            for (const auto& e : extra) given = given || e == flag;
            if (!given) {
                a.push_back(flag);
                a.push_back(value);
            }
        }
        a.insert(a.end(), extra.begin(), extra.end());
        return a;
    }
};

} // namespace inputs_test

// A small harness for the input-format CLI tests (test_bad_input, test_inputs): each test runs
// the built `licvdb` (LICVDB_EXE) in its own temporary directory and captures stdout, stderr
// and the exit status; helpers write .npy / .vti fixtures byte by byte.
#pragma once

#include <gtest/gtest.h>

#include <openvdb/openvdb.h>

#include <atomic>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace inputs_test {

namespace fs = std::filesystem;

struct RunResult
{
    int code = -1;
    std::string out, err, command;
    std::string describe() const
    {
        return "command: " + command + "\nexit: " + std::to_string(code) + "\n--- stdout ---\n" + out
               + "\n--- stderr ---\n" + err + "\n";
    }
};

inline std::string shellQuote(const std::string& s)
{
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

inline std::string readText(const fs::path& p)
{
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

inline void writeBytes(const fs::path& p, const std::string& bytes)
{
    std::ofstream out(p, std::ios::binary);
    out << bytes;
}

inline std::string lower(std::string s)
{
    for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
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

class InputsTest : public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        for (char& c : name)
            if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
        mRoot = fs::temp_directory_path()
                / ("licvdb_test_inputs_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + "_" + name);
        fs::remove_all(mRoot);
        fs::create_directories(mRoot / "work");
        fs::create_directories(mRoot / "logs");
    }
    void TearDown() override
    {
        std::error_code ec;
        if (!HasFailure()) fs::remove_all(mRoot, ec);
        else std::cerr << "kept test directory " << mRoot << "\n";
    }
    fs::path work(const std::string& name = "") const { return name.empty() ? mRoot / "work" : mRoot / "work" / name; }

    RunResult runCommand(const std::string& command)
    {
        const int n = mRuns++;
        const fs::path outFile = mRoot / "logs" / ("stdout." + std::to_string(n));
        const fs::path errFile = mRoot / "logs" / ("stderr." + std::to_string(n));
        RunResult r;
        r.command = command;
        const std::string cmd = "cd " + shellQuote(work().string()) + " && " + command + " </dev/null >"
                                + shellQuote(outFile.string()) + " 2>" + shellQuote(errFile.string());
        const int status = std::system(cmd.c_str());
        if (status == -1) r.code = -1;
        else if (WIFEXITED(status)) r.code = WEXITSTATUS(status);
        else if (WIFSIGNALED(status)) r.code = 128 + WTERMSIG(status);
        r.out = readText(outFile);
        r.err = readText(errFile);
        return r;
    }

    RunResult run(const std::vector<std::string>& args)
    {
        std::string c = shellQuote(LICVDB_EXE);
        for (const auto& a : args) c += " " + shellQuote(a);
        return runCommand(c);
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

protected:
    fs::path mRoot;
    int mRuns = 0;
};

} // namespace inputs_test

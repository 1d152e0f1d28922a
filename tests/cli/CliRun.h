// Running the built `licvdb` (LICVDB_EXE) from the CLI tests (test_cli, test_render_cli,
// test_bad_input, test_inputs): a shell command in a chosen directory with stdin from /dev/null,
// stdout and stderr captured through files, and the exit status decoded.
#pragma once

#include <atomic>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>

namespace cli_test {

namespace fs = std::filesystem;

struct RunResult
{
    int code = -1; ///< exit status; 128 + signal if killed by a signal; -1 if it could not run
    std::string out;
    std::string err;
    std::string command;

    /// For assertion messages.
    std::string describe() const
    {
        return "command: " + command + "\nexit: " + std::to_string(code) + "\n--- stdout ---\n" + out +
               "\n--- stderr ---\n" + err + "\n";
    }
};

inline std::string shellQuote(const std::string& s)
{
    std::string q = "'";
    for (char c : s) {
        if (c == '\'') q += "'\\''";
        else q += c;
    }
    return q + "'";
}

inline std::string readText(const fs::path& p)
{
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

inline std::string lower(std::string s)
{
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

/// `licvdb ARGS...`, every argument shell-quoted.
inline std::string licvdbCommand(const std::vector<std::string>& args)
{
    std::string c = shellQuote(LICVDB_EXE);
    for (const auto& a : args) {
        c += ' ';
        c += shellQuote(a); // not `" " + ...`: GCC 12 warns falsely (-Wrestrict, PR 105329)
    }
    return c;
}

/// Run the shell `command` in `dir`; stdout and stderr go through numbered files in `logs`.
inline RunResult runShell(const fs::path& dir, const fs::path& logs, const std::string& command)
{
    static std::atomic<int> counter{0};
    const std::string n = std::to_string(counter++);
    const fs::path outFile = logs / ("stdout." + n), errFile = logs / ("stderr." + n);
    RunResult r;
    r.command = command;
    const std::string cmd = "cd " + shellQuote(dir.string()) + " && " + command + " </dev/null >" +
                            shellQuote(outFile.string()) + " 2>" + shellQuote(errFile.string());
    const int status = std::system(cmd.c_str());
    if (status == -1) r.code = -1;
    else if (WIFEXITED(status)) r.code = WEXITSTATUS(status);
    else if (WIFSIGNALED(status)) r.code = 128 + WTERMSIG(status);
    r.out = readText(outFile);
    r.err = readText(errFile);
    return r;
}

/// Run `licvdb ARGS...` in `dir` (see runShell).
inline RunResult runLicvdb(const fs::path& dir, const fs::path& logs, const std::vector<std::string>& args)
{
    return runShell(dir, logs, licvdbCommand(args));
}

} // namespace cli_test

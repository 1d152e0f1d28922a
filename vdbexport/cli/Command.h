// The commands of `licvdb`, one table (pbrt-v4's cmd/, OCIO's tools): each command adds its own
// options to a CLI11 subcommand and runs when that subcommand was parsed. main() builds the
// program from the table; `licvdb help CMD` and its error message read the same table.
#pragma once

#include "vdbexport/bake/Distributed.h"
#include "vdbexport/cli/TerminalProgress.h"

#include <CLI/CLI.hpp>

#include <memory>
#include <span>
#include <string>
#include <vector>

namespace vdbexport::cli {

/// The options every working command has (field, bake, render, info): --progress, --quiet,
/// --json, --threads.
struct CommonOptions
{
    bool quiet = false;
    bool json = false;
    int threads = 0; ///< worker threads of every parallel stage; 0 = all cores
    std::string progress = "bar";
    CLI::Option* threadsOption = nullptr; ///< to tell whether --threads was given

    TerminalProgress::Style progressStyle() const
    {
        return progress == "lines" ? TerminalProgress::Style::Lines : TerminalProgress::Style::Bar;
    }
};

/// Add the CommonOptions flags to `cmd` (after the command's own, so they come last in its help).
void addCommonOptions(CLI::App& cmd, CommonOptions& options);

/// What a command's run may need beyond its own options.
struct Context
{
    CLI::App& app;    ///< the whole program (help prints its synopsis or a command's help)
    int& argc;        ///< main's arguments (MPI may take some)
    char**& argv;
    MpiSession& mpi;  ///< started by a bake under mpirun; main reports errors through it
};

/// One subcommand. Its CLI11 variables live in the object, so it must outlive the parse.
class Command
{
public:
    virtual ~Command() = default;
    /// Add the options, positional arguments and footer (examples) to `cmd`.
    virtual void addOptions(CLI::App& cmd) = 0;
    /// Run after a successful parse; returns the exit code.
    /// @throw as the library does (lic::InputError, lic::Cancelled, ...): only main() catches.
    virtual int run(Context& context) = 0;
    /// The common options, or null for a command without them (help, version). With them, main()
    /// bounds the run's threads to --threads and names errors `licvdb CMD: error: ...`.
    virtual const CommonOptions* common() const { return nullptr; }
};

/// A command with the common options (field, bake, render, info). Its addOptions() adds them
/// with addCommonOptions(cmd, mCommon), after its own.
class CommandWithCommonOptions : public Command
{
public:
    const CommonOptions* common() const final { return &mCommon; }

protected:
    CommonOptions mCommon;
};

/// One row of the command table.
struct CommandEntry
{
    const char* name;
    const char* description; ///< one line, for the synopsis
    std::unique_ptr<Command> (*make)();
    bool helpTopic = true;   ///< named in `licvdb help`'s list of commands
};

/// Every command of licvdb in synopsis order: field, convert, bake, render, info, help, version.
std::span<const CommandEntry> commandTable();

/// The commands that have help of their own, as prose: "field, bake, render or info".
std::string helpTopics(const char* lastSeparator);

/// The names of licvdb's choices, from their tables (lic's engines, kernels, spot distributions,
/// derived scalars and colormaps; the input formats of vdbexport/io/InputFormats.h, "auto"
/// first): `licvdb help --json` prints them and the help texts list them.
struct Choices
{
    std::vector<std::string> engines, kernels, distributions, scalars, colormaps, formats;
};
Choices choices();
/// "a|b|c" (or with another separator).
std::string joined(const std::vector<std::string>& names, const char* separator = "|");

/// True in the child process that checks a .vdb before this program reads it
/// (LICVDB_READ_CHILD=1, see vdbexport::setReadIsolation).
bool inReadChild();

/// The program's own help: synopsis, commands and footer (App::help() would describe the
/// parsed subcommand instead).
std::string synopsis(CLI::App& app);

std::unique_ptr<Command> makeFieldCommand();
std::unique_ptr<Command> makeConvertCommand();
std::unique_ptr<Command> makeBakeCommand();
std::unique_ptr<Command> makeRenderCommand();
std::unique_ptr<Command> makeInfoCommand();
std::unique_ptr<Command> makeHelpCommand();
std::unique_ptr<Command> makeVersionCommand();

} // namespace vdbexport::cli

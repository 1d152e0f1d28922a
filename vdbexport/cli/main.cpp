// licvdb: bake 3D line integral convolution of vector fields into OpenVDB volumes.
//
// The commands (field, bake, render, info, help, version) are the table of Command.h, one file
// each. Only main() catches: lic::InputError and usage errors exit 2, other failures exit 1.
// Progress goes to stderr when it is a terminal; --json puts a machine-readable summary on stdout.

#include "Allocator.h"
#include "Command.h"

#include "vdbexport/bake/Distributed.h"
#include "vdbexport/io/Program.h"
#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/ReadCheck.h"

#include <lic/util/Error.h>
#include <lic/util/Parallel.h>

#include <CLI/CLI.hpp>

#include <openvdb/openvdb.h>

#include <cstdlib>
#include <iostream>
#include <new>
#include <vector>

namespace {

using namespace vdbexport::cli;

/// A command of the table, added to the program as a subcommand.
struct Registered
{
    const CommandEntry* entry;
    CLI::App* app;
    std::unique_ptr<Command> command;
};

/// Run the parsed command with at most --threads threads in every parallel stage. What it throws
/// is reported as `licvdb CMD: error: ...` (by the ranks that should, under MPI) and becomes the
/// exit code: 2 for bad input, 1 otherwise.
int runCommand(const Registered& r, Context& context)
{
    const CommonOptions* common = r.command->common();
    const std::string who = common ? std::string("licvdb ") + r.entry->name : std::string("licvdb");
    vdbexport::MpiSession& mpi = context.mpi;
    try {
        const lic::ThreadLimit threadLimit(common ? common->threads : 0);
        return r.command->run(context);
    } catch (const lic::Cancelled&) {
        if (mpi.reportsErrors()) std::cerr << who << ": cancelled; no output written\n";
        return mpi.failed(1);
    } catch (const lic::InputError& e) {
        if (mpi.reportsErrors()) {
            std::cerr << who << ": error: " << mpi.errorPrefix() << e.what() << "\n";
            std::cerr << "see `licvdb help " << (common ? r.entry->name : "") << "`\n";
        }
        return mpi.failed(2);
    } catch (const std::bad_alloc&) {
        if (mpi.reportsErrors()) std::cerr << who << ": error: " << mpi.errorPrefix() << "out of memory\n";
        return mpi.failed(1);
    } catch (const std::exception& e) {
        if (mpi.reportsErrors()) std::cerr << who << ": error: " << mpi.errorPrefix() << e.what() << "\n";
        return mpi.failed(1);
    }
}

} // namespace

int main(int argc, char** argv)
{
    // Layer 2 of the .vdb read defences: every read first runs in a child `licvdb info --check`
    // (for a .vdb, licvdb-readcheck where it is installed: it starts faster than licvdb).
    if (!inReadChild()) {
        // From a bundle, children start through its launcher (bin/licvdb), which runs them with the
        // bundle's loader; licvdb-readcheck would start with the host's loader, so it is not used.
        const std::string self = vdbexport::program::restartPath();
        vdbexport::setReadIsolation(self, vdbexport::program::inBundle() ? std::string()
                                                                          : vdbexport::findVdbReadHelper(self));
    }
    // Layer 2's checks are forked from a server process made now, while this process runs no
    // thread of its own yet (TBB starts with the command; log4cplus, which OpenVDB links, has
    // started idle ones, which a fork does not copy): a forked check starts in a few
    // milliseconds, licvdb-readcheck in 50–80 ms (most of it linking OpenVDB).
    // LICVDB_READ_FORK=0 starts a program per check instead.
    // OpenVDB's type registry is set up first, for the server's children to inherit (10 ms each).
    const char* forkSetting = std::getenv("LICVDB_READ_FORK");
    const bool forkOff = forkSetting && std::string(forkSetting) == "0";
    if (!inReadChild() && !vdbexport::readIsolationExecutable().empty() && !forkOff) {
        openvdb::initialize();
        vdbexport::startReadCheckServer(
            [](const std::string& path) {
                useFreshArena();
                return vdbexport::detail::readCheckMain(path, "licvdb-readcheck");
            });
    }

    CLI::App app{"licvdb: 3D line integral convolution of vector fields, baked into OpenVDB volumes"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("licvdb ") + LICVDB_VERSION);
    app.footer("Run `licvdb help CMD` for a command's options and examples.");
    // A distributed bake under mpirun/srun; started only for `bake` (see vdbexport/bake/Distributed.h).
    vdbexport::MpiSession mpi;
    std::vector<Registered> commands;
    for (const CommandEntry& entry : commandTable()) {
        Registered r{&entry, app.add_subcommand(entry.name, entry.description), entry.make()};
        r.command->addOptions(*r.app);
        commands.push_back(std::move(r));
    }

    if (argc < 2) { // no command at all: say what there is, not only that something is missing
        std::cerr << synopsis(app);
        return 2;
    }
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) { // also --help and --version, which exit 0
        const int code = app.exit(e);
        if (code != 0) std::cerr << "see `licvdb help` or `licvdb help COMMAND`\n";
        return code == 0 ? 0 : 2;
    }
    Context context{app, argc, argv, mpi};
    for (const Registered& r : commands)
        if (r.app->parsed()) return runCommand(r, context);
    return 0;
}

// The command table and what the commands share.
#include "Command.h"

#include "vdbexport/io/InputFormats.h"

#include <lic/composite/Colormap.h>
#include <lic/engine/Engine.h>
#include <lic/engine/Settings.h>
#include <lic/field/Scalars.h>
#include <lic/texture/Spots.h>
#include <lic/util/Names.h>

#include <array>
#include <cstdlib>

namespace vdbexport::cli {

namespace {

const std::array<CommandEntry, 7> kCommands{{
    {"field", "Write an analytic example vector field", makeFieldCommand},
    {"convert", "Resample a CFD mesh (VTK, PLOT3D, OpenFOAM) or any field to a .vdb", makeConvertCommand},
    {"bake", "Bake a LIC volume from a vector field", makeBakeCommand},
    {"render", "Raycast a baked .vdb to an image (reference halo renderer)", makeRenderCommand},
    {"info", "List the grids, bounding boxes and metadata of a .vdb", makeInfoCommand},
    {"help", "Show help for a command", makeHelpCommand, false},
    {"version", "Print the version", makeVersionCommand, false},
}};

} // namespace

std::span<const CommandEntry> commandTable() { return kCommands; }

Choices choices()
{
    Choices c;
    for (const lic::EngineInfo& e : lic::engines()) c.engines.emplace_back(e.name);
    c.kernels = lic::listedNames(lic::kernelNames());
    c.distributions = lic::listedNames(lic::spotDistributionNames());
    c.scalars = lic::derivedScalarNames();
    c.colormaps = lic::Colormap::names();
    c.formats = inputFormatValues();
    return c;
}

std::string joined(const std::vector<std::string>& names, const char* separator)
{
    std::string out;
    for (const std::string& n : names) out += (out.empty() ? "" : separator) + n;
    return out;
}

std::string helpTopics(const char* lastSeparator)
{
    std::vector<std::string> names;
    for (const CommandEntry& c : kCommands)
        if (c.helpTopic) names.emplace_back(c.name);
    std::string out;
    for (std::size_t i = 0; i < names.size(); ++i)
        out += (i == 0 ? "" : i + 1 == names.size() ? lastSeparator : ", ") + names[i];
    return out;
}

bool inReadChild()
{
    const char* v = std::getenv("LICVDB_READ_CHILD");
    return v && std::string(v) == "1";
}

std::string synopsis(CLI::App& app)
{
    return app.get_formatter()->make_help(&app, app.get_name().empty() ? "licvdb" : app.get_name(),
                                          CLI::AppFormatMode::Normal);
}

void addCommonOptions(CLI::App& cmd, CommonOptions& c)
{
    cmd.add_option("--progress", c.progress,
                   "bar: a progress bar when stderr is a terminal; lines: one `progress FRACTION STAGE` "
                   "line per update on stderr, for programs [bar]")
        ->check(CLI::IsMember({"bar", "lines"}));
    cmd.add_flag("-q,--quiet", c.quiet, "No progress or messages on stderr");
    cmd.add_flag("--json", c.json, "Print a machine-readable JSON summary on stdout");
    c.threadsOption = cmd.add_option("--threads", c.threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024));
}

} // namespace vdbexport::cli

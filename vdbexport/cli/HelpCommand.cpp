// `licvdb help [CMD]` and `licvdb version`.
#include "Command.h"
#include "Allocator.h"

#include <lic/util/Error.h>

#include <nlohmann/json.hpp>

#include <iostream>

namespace vdbexport::cli {

namespace {

class HelpCommand final : public Command
{
public:
    void addOptions(CLI::App& cmd) override
    {
        cmd.add_option("command", mTopic, helpTopics(", "));
        cmd.add_flag("--json", mJson,
                     "Print licvdb's choices as JSON: engines, kernels, spot distributions, derived scalars, colormaps "
                     "(for programs, e.g. the Blender add-on's tests)");
    }

    int run(Context& context) override
    {
        if (mJson) {
            const Choices c = choices();
            const nlohmann::json j = {{"version", LICVDB_VERSION}, {"engines", c.engines}, {"kernels", c.kernels},
                                      {"distributions", c.distributions}, {"scalars", c.scalars},
                                      {"colormaps", c.colormaps}};
            std::cout << j.dump(2) << "\n";
            return 0;
        }
        if (mTopic.empty()) {
            std::cout << synopsis(context.app);
            return 0;
        }
        CLI::App* sub = nullptr;
        try {
            sub = context.app.get_subcommand(mTopic);
        } catch (const CLI::OptionNotFound&) {
        }
        if (!sub) throw lic::InputError("no command \"" + mTopic + "\"; expected " + helpTopics(" or "));
        std::cout << sub->help();
        return 0;
    }

private:
    std::string mTopic;
    bool mJson = false;
};

class VersionCommand final : public Command
{
public:
    void addOptions(CLI::App&) override {}

    int run(Context&) override
    {
        std::cout << "licvdb " << LICVDB_VERSION << "\n" << "allocator: " << allocatorDescription() << "\n";
        return 0;
    }
};

} // namespace

std::unique_ptr<Command> makeHelpCommand() { return std::make_unique<HelpCommand>(); }
std::unique_ptr<Command> makeVersionCommand() { return std::make_unique<VersionCommand>(); }

} // namespace vdbexport::cli

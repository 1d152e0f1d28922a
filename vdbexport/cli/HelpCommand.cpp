// `licvdb help [CMD]` and `licvdb version`.
#include "Command.h"
#include "Allocator.h"

#include <lic/util/Error.h>

#include <iostream>

namespace vdbexport::cli {

namespace {

class HelpCommand final : public Command
{
public:
    void addOptions(CLI::App& cmd) override { cmd.add_option("command", mTopic, helpTopics(", ")); }

    int run(Context& context) override
    {
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

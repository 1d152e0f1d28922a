// `licvdb help [CMD]` and `licvdb version`.
#include "Command.h"
#include "Allocator.h"

#include "vdbexport/io/InputFormats.h"

#include <lic/composite/OutputGrids.h>
#include <lic/engine/Engine.h>
#include <lic/util/Error.h>

#include <nlohmann/json.hpp>

#include <iostream>

namespace vdbexport::cli {

namespace {

/// The output-grid table (lic/composite/OutputGrids.h): what a bake can write.
nlohmann::json outputGridsJson()
{
    static const char* const kWhen[] = {"always", "spots", "asked", "color"};
    nlohmann::json out = nlohmann::json::array();
    for (const lic::OutputGridRow& row : lic::outputGrids()) {
        const std::string name(row.name);
        nlohmann::json meta = nlohmann::json::array();
        for (const auto& [key, value] : row.fixedMeta) meta.push_back({{"key", key}, {"value", value}});
        out.push_back({{"name", row.perLevel ? name + "<k>" : name}, {"type", row.type},
                       {"when", kWhen[std::size_t(row.when)]},
                       {"recipe_key", row.recipeKey.empty() ? "" : "output." + std::string(row.recipeKey)},
                       {"flag", row.flag}, {"help", row.help}, {"fill", row.fill}, {"metadata", row.metadata}, {"fixed_metadata", meta},
                       {"blender", row.blender}, {"per_level", row.perLevel}, {"per_frame", row.perFrame}});
    }
    return out;
}

/// The engine table (lic/engine/Engine.h): each engine's summary, inputs and the lic keys it reads.
nlohmann::json engineTableJson()
{
    nlohmann::json out = nlohmann::json::array();
    for (const lic::EngineInfo& e : lic::engines()) {
        nlohmann::json keys = nlohmann::json::array();
        for (std::string_view k : e.keys) keys.push_back("lic." + std::string(k));
        out.push_back({{"name", e.name}, {"summary", e.summary}, {"noise", e.noiseBricks != nullptr},
                       {"spots", e.spotBricks != nullptr}, {"keys", keys}});
    }
    return out;
}

class HelpCommand final : public Command
{
public:
    void addOptions(CLI::App& cmd) override
    {
        cmd.add_option("command", mTopic, helpTopics(", "));
        cmd.add_flag("--json", mJson,
                     "Print licvdb's choices as JSON: engines, kernels, spot distributions, derived scalars, colormaps, "
                     "input formats, output grids (for programs, e.g. the Blender add-on's tests)");
    }

    int run(Context& context) override
    {
        if (mJson) {
            const Choices c = choices();
            nlohmann::json j = {{"version", LICVDB_VERSION}, {"engines", c.engines}, {"kernels", c.kernels},
                                {"distributions", c.distributions}, {"scalars", c.scalars}, {"colormaps", c.colormaps},
                                {"formats", nlohmann::json::array()}};
            for (const InputFormat& f : inputFormats())
                j["formats"].push_back({{"name", f.name}, {"extensions", f.extensions}, {"kind", kindName(f.kind)},
                                        {"description", f.description}});
            j["grids"] = outputGridsJson();
            j["engine_table"] = engineTableJson();
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

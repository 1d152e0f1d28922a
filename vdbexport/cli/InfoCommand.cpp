// `licvdb info`: describe a .vdb, or with --check only say whether it is intact.
#include "Command.h"

#include "vdbexport/io/Info.h"
#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/ReadCheck.h"

#include <lic/util/Error.h>

#include <iostream>

namespace vdbexport::cli {

namespace {

class InfoCommand final : public CommandWithCommonOptions
{
public:
    void addOptions(CLI::App& cmd) override;

    int run(Context&) override
    {
        if (mCheck) return check();
        const nlohmann::json d = describeVdb(mPath);
        std::cout << (mCommon.json ? d.dump(2) + "\n" : formatInfo(d));
        return 0;
    }

private:
    int check() const;

    std::string mPath;
    bool mCheck = false;
};

void InfoCommand::addOptions(CLI::App& cmd)
{
    cmd.add_option("file", mPath, "A .vdb file")->required();
    cmd.add_flag("--check", mCheck, "Only check that the file is intact: exit 0 if it is, 2 with the reason if it is not");
    addCommonOptions(cmd, mCommon);
    cmd.footer("--check walks the file's whole structure (every size and offset it stores, every leaf\n"
               "buffer decoded), then reads every grid with OpenVDB in a child process, so a file that would\n"
               "crash or hang a reader is refused with exit 2 instead. Every licvdb command that reads a\n"
               ".vdb (bake, render, info) does the same first; see docs/inputs.md.\n\n"
               "Examples:\n  licvdb info jet_lic.vdb\n  licvdb info jet_lic.vdb --json | python3 -m json.tool\n"
               "  licvdb info --check download.vdb && echo intact\n"
               "  licvdb info --check download.vdb --json     # {\"ok\": false, \"error\": \"...\"} on stdout too\n");
}

/// `licvdb info --check FILE`: layers 1 and 2 (docs/inputs.md); in the child that layer 2 starts
/// (LICVDB_READ_CHILD=1), layer 1 and then a full read and description of every grid in-process.
int InfoCommand::check() const
{
    nlohmann::json out{{"path", mPath}};
    try {
        const VdbCheckResult r = detail::checkedVdb(mPath);
        if (inReadChild()) (void)describeVdb(mPath);
        out["ok"] = true;
        out["file_version"] = r.fileVersion;
        out["grids"] = nlohmann::json::array();
        std::string list;
        for (const auto& g : r.grids) {
            nlohmann::json j{{"name", g.name}, {"grid_type", g.gridType}, {"value_type", g.valueType},
                             {"half_float", g.halfFloat}, {"compression", g.compression}, {"tiles", g.tiles},
                             {"internal_nodes", g.internalNodes}, {"leaves", g.leaves}};
            if (g.instance) j["instance_of"] = g.instanceParent;
            if (!g.skipReason.empty()) j["skipped"] = g.skipReason;
            out["grids"].push_back(j);
            list += (list.empty() ? "" : ", ") + g.name + " (" + (g.valueType.empty() ? g.gridType : g.valueType) + ")";
        }
        if (mCommon.json) std::cout << out.dump(2) << "\n";
        else if (!mCommon.quiet) std::cout << mPath << ": intact (" << r.grids.size() << " grid" << (r.grids.size() == 1 ? "" : "s")
                                           << (list.empty() ? "" : ": " + list) << ")\n";
        return 0;
    } catch (const lic::InputError& e) {
        if (mCommon.json) {
            out["ok"] = false;
            out["error"] = e.what();
            std::cout << out.dump(2) << "\n";
        }
        throw;
    }
}

} // namespace

std::unique_ptr<Command> makeInfoCommand() { return std::make_unique<InfoCommand>(); }

} // namespace vdbexport::cli

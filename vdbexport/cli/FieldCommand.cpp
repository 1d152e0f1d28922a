// `licvdb field`: write an analytic example field (lic/field/Presets.h), or a sequence of it.
#include "Command.h"

#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/io/Numbers.h"
#include "vdbexport/io/OutputSet.h"

#include <nlohmann/json.hpp>

#include <lic/field/Presets.h>
#include <lic/util/Error.h>

#include <cmath>
#include <iostream>
#include <limits>

namespace vdbexport::cli {

namespace {

/// --res: X,Y,Z or one number for a cube.
openvdb::Coord parseResolution(const std::string& text)
{
    const char* expected = "X,Y,Z (e.g. 64,64,64) or one number";
    const std::vector<double> v = parseNumberList("--res", text, expected);
    if (v.size() != 1 && v.size() != 3) throw lic::InputError("--res \"" + text + "\" needs 1 or 3 numbers (X,Y,Z)");
    for (double x : v)
        if (x != std::floor(x) || std::abs(x) > double(std::numeric_limits<int>::max()))
            throw lic::InputError("--res \"" + text + "\" is not a resolution; expected " + expected);
    return v.size() == 1 ? openvdb::Coord(int(v[0])) : openvdb::Coord(int(v[0]), int(v[1]), int(v[2]));
}

std::string presetList()
{
    std::string out;
    for (const auto& name : lic::presetNames())
        out += "  " + name + std::string(name.size() < 12 ? 12 - name.size() : 1, ' ') +
               lic::presetDescription(name) + "\n";
    return out;
}

class FieldCommand final : public CommandWithCommonOptions
{
public:
    void addOptions(CLI::App& cmd) override;
    int run(Context& context) override;

private:
    /// The frame numbers to write: {0} for a single field, else --frames FIRST..LAST.
    std::vector<int> frameNumbers() const;

    std::string mPreset, mRes, mOut, mFrames;
    double mFps = 24;
};

void FieldCommand::addOptions(CLI::App& cmd)
{
    cmd.add_option("preset", mPreset, "Preset name")->required();
    cmd.add_option("--res", mRes, "Resolution X,Y,Z in voxels (default per preset)");
    cmd.add_option("-o,--out", mOut, "Output .vdb (with --frames: a pattern with #### for the frame number)")->required();
    cmd.add_option("--frames", mFrames, "FIRST,LAST: write a sequence, frame n at time n/fps (tornado moves; the others are steady)");
    cmd.add_option("--fps", mFps, "With --frames: frames per time unit of the field [24]");
    addCommonOptions(cmd, mCommon);
    cmd.footer("Presets:\n" + presetList() +
               "\nExamples:\n  licvdb field abc --res 64,64,64 --out abc.vdb\n"
               "  licvdb field tabbed-jet --out jet.vdb      # 101x101x148, with `temperature`\n"
               "  licvdb field tornado --frames 1,48 --out tornado_####.vdb   # an unsteady sequence\n");
}

std::vector<int> FieldCommand::frameNumbers() const
{
    if (mFrames.empty()) return {0};
    const auto [first, last] = parseFrameRange("--frames", mFrames);
    if (!(mFps > 0) || !std::isfinite(mFps)) throw lic::InputError("--fps must be > 0");
    if (!isFramePattern(mOut))
        throw lic::InputError("--out \"" + mOut + "\": with --frames, put #### where the frame number goes");
    std::vector<int> numbers;
    for (int n = first; n <= last; ++n) numbers.push_back(n);
    return numbers;
}

int FieldCommand::run(Context&)
{
    const openvdb::Coord r = mRes.empty() ? lic::presetDefaultResolution(mPreset) : parseResolution(mRes);
    const std::vector<int> numbers = frameNumbers();
    OutputSet outputs; // all frames appear together, or none
    openvdb::GridPtrVec grids;
    std::vector<std::string> written;
    for (int n : numbers) {
        const double time = mFrames.empty() ? 0.0 : double(n) / mFps;
        const lic::PresetField f = lic::makePresetField(mPreset, r, time);
        grids = {f.velocity};
        for (const auto& s : f.scalars) grids.push_back(s);
        written.push_back(mFrames.empty() ? mOut : expandFramePattern(mOut, n));
        outputs.addVdb(written.back(), grids);
    }
    outputs.commit();
    if (mCommon.json) {
        nlohmann::json j{{"output", mOut}, {"preset", mPreset}, {"resolution", {r[0], r[1], r[2]}},
                         {"grids", nlohmann::json::array()}, {"files", written}};
        for (const auto& g : grids) j["grids"].push_back(g->getName());
        std::cout << j.dump(2) << "\n";
    } else if (!mCommon.quiet) {
        std::cerr << "wrote " << mPreset << " field " << r[0] << "x" << r[1] << "x" << r[2] << " to " << mOut << "\n";
    }
    return 0;
}

} // namespace

std::unique_ptr<Command> makeFieldCommand() { return std::make_unique<FieldCommand>(); }

} // namespace vdbexport::cli

// `licvdb convert`: any field licvdb reads (CFD meshes through VTK, dense arrays, .vdb) written
// as a .vdb of a Vec3 `velocity` grid and its scalars, or a numbered sequence for a series.
#include "Command.h"
#include "Progress.h"

#include "vdbexport/io/FieldInput.h"
#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/io/InputFormats.h"
#include "vdbexport/io/MeshInput.h"
#include "vdbexport/io/Numbers.h"
#include "vdbexport/io/OutputSet.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <sstream>

namespace vdbexport::cli {

namespace {

using json = nlohmann::json;

class ConvertCommand final : public CommandWithCommonOptions
{
public:
    void addOptions(CLI::App& cmd) override;
    int run(Context& context) override;

private:
    FieldSpec spec() const;
    /// The times to write: {} for a single field (no series), else the chosen ones.
    std::vector<double> chooseTimes(const std::string& format) const;
    int list(const std::string& format) const;

    std::string mInput, mOut, mFormat = "auto", mGrid, mCrop, mFrames, mSolution, mNan = "refuse";
    double mVoxelSize = 0, mTime = 0;
    bool mList = false;
    CLI::Option* mVoxelOption = nullptr;
    CLI::Option* mTimeOption = nullptr;
};

void ConvertCommand::addOptions(CLI::App& cmd)
{
    std::vector<std::string> meshes; // each mesh format's usual extension, then what a row picks by path
    for (const InputFormat& f : inputFormats())
        if (f.kind == InputKind::Mesh && std::find(meshes.begin(), meshes.end(), f.extensions.front()) == meshes.end())
            meshes.push_back(f.extensions.front());
    std::string byPath;
    for (const InputFormat& f : inputFormats())
        if (f.matchesPath) byPath += ", " + f.description;
    cmd.add_option("input", mInput, "Field to convert: a mesh (" + joined(meshes, " ") + byPath + ") or any field bake reads")
        ->required();
    cmd.add_option("-o,--out", mOut, "Output .vdb; for a series, a pattern with #### for the time step's index");
    cmd.add_option("--format", mFormat, "Input format: " + inputFormatHelp() + " [auto: by extension]");
    cmd.add_option("--grid", mGrid, "Velocity array (default: U, velocity, vel, v, the only vector array)");
    mVoxelOption = cmd.add_option("--voxel-size", mVoxelSize, "Voxel size of the lattice, world units [for LIC: half the 10th percentile of the cell sizes, within a budget; --list shows it]")
                       ->check(CLI::PositiveNumber);
    cmd.add_option("--crop", mCrop, "Resample inside world box X0,Y0,Z0,X1,Y1,Z1 only [the mesh's bounds]");
    mTimeOption = cmd.add_option("--time", mTime, "A series: the time to convert [the latest]");
    cmd.add_option("--frames", mFrames, "A series: time steps FIRST,LAST (indices from 0, as --list shows) into a "
                                        "#### pattern [every step when --out has ####]");
    cmd.add_option("--solution", mSolution, "PLOT3D: the solution (.q) file [the grid's name with .q]");
    cmd.add_option("--nan-policy", mNan, "refuse|zero: NaN/Inf velocity is an error, or set to 0 [refuse]")
        ->check(CLI::IsMember({"refuse", "zero"}));
    cmd.add_flag("--list", mList, "Print the mesh's cells, bounds, cell sizes, default voxel size, arrays and times, and write nothing");
    addCommonOptions(cmd, mCommon);
    cmd.footer("The output has a Vec3 grid `velocity` (the velocity array resampled) and one float grid per scalar\n"
               "array, active on the voxels inside the mesh; metadata source, source_format, source_array and\n"
               "source_time (series) name where they came from. A series becomes files that\n"
               "`bake --field 'out_####.vdb' --field-frames` reads.\n"
               "\nExamples:\n"
               "  licvdb convert cavity/ --list                      # an OpenFOAM case: arrays, times\n"
               "  licvdb convert cavity/ --out cavity.vdb            # its latest time\n"
               "  licvdb convert cavity/ --out cavity_####.vdb       # every time step\n"
               "  licvdb convert wing.vtu --voxel-size 0.01 --out wing.vdb\n"
               "  licvdb convert blade.xyz --solution blade.q --out blade.vdb   # PLOT3D\n"
               "  licvdb bake --field wing.vtu --out wing_lic.vdb    # bake reads meshes directly too\n");
}

FieldSpec ConvertCommand::spec() const
{
    FieldSpec s;
    s.path = mInput;
    s.format = mFormat;
    s.grid = mGrid;
    s.nanPolicy = mNan;
    s.solution = mSolution;
    if (mVoxelOption->count()) s.voxelSize = mVoxelSize;
    if (!mCrop.empty()) {
        const auto v = parseNumberList("--crop", mCrop, "X0,Y0,Z0,X1,Y1,Z1 (world units)", 6);
        for (int a = 0; a < 3; ++a)
            if (!(v[a] < v[a + 3])) throw lic::InputError("--crop \"" + mCrop + "\": X0 < X1, Y0 < Y1 and Z0 < Z1 are needed");
        s.crop = std::array<std::array<double, 3>, 2>{{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}}};
    }
    return s;
}

std::vector<double> ConvertCommand::chooseTimes(const std::string& format) const
{
    const std::vector<double> times = isMeshFormat(format) ? meshTimes(mInput, format) : std::vector<double>{};
    const bool pattern = !mOut.empty() && isFramePattern(mOut);
    if (mTimeOption->count() && !mFrames.empty()) throw lic::InputError("--time and --frames exclude each other");
    if (mTimeOption->count()) {
        if (times.empty()) throw lic::InputError("--time: '" + mInput + "' is a single field, not a series (.pvd, OpenFOAM)");
        if (pattern) throw lic::InputError("--out \"" + mOut + "\" is a pattern, but --time writes one file");
        return {mTime};
    }
    if (!mFrames.empty()) {
        if (times.empty()) throw lic::InputError("--frames: '" + mInput + "' is a single field, not a series (.pvd, OpenFOAM)");
        const auto [first, last] = parseFrameRange("--frames", mFrames);
        if (std::size_t(last) >= times.size())
            throw lic::InputError("--frames " + mFrames + ": '" + mInput + "' has " + std::to_string(times.size())
                                  + " time steps (0 to " + std::to_string(times.size() - 1) + ")");
        if (!pattern) throw lic::InputError("--out \"" + mOut + "\": with --frames, put #### where the step's index goes");
        return std::vector<double>(times.begin() + first, times.begin() + last + 1);
    }
    if (pattern) {
        if (times.empty())
            throw lic::InputError("--out \"" + mOut + "\" is a pattern, but '" + mInput + "' is a single field, not a series");
        return times;
    }
    return {};
}

int ConvertCommand::list(const std::string& format) const
{
    if (!isMeshFormat(format))
        throw lic::InputError("--list describes meshes; '" + mInput + "' is a " + format + " field (licvdb info reads .vdb files)");
    MeshOptions options;
    options.solution = mSolution;
    if (mTimeOption->count()) options.time = mTime;
    const MeshSummary s = describeMesh(mInput, format, options);
    json j{{"input", mInput}, {"format", s.format}, {"cells", s.cells}, {"points", s.points}, {"blocks", s.blocks},
           {"bounds", s.bounds}, {"median_cell_size", s.medianCellSize},
           {"default_voxel_size", s.defaultVoxelSize}, {"voxel_size_rule", s.voxelSizeRule}, {"times", s.times}, {"arrays", json::array()}};
    if (s.time) j["time"] = *s.time;
    if (!s.timeSources.empty()) j["time_sources"] = s.timeSources;
    j["warnings"] = s.warnings;
    for (const auto& a : s.arrays)
        j["arrays"].push_back({{"name", a.name}, {"components", a.components}, {"on", a.cellData ? "cells" : "points"}});
    if (mCommon.json) {
        std::cout << j.dump(2) << "\n";
        return 0;
    }
    std::cout << mInput << ": " << s.format << ", " << s.cells << " cells, " << s.points << " points"
              << (s.blocks > 1 ? ", " + std::to_string(s.blocks) + " blocks" : "") << "\n";
    std::cout << "  bounds (" << s.bounds[0][0] << ", " << s.bounds[0][1] << ", " << s.bounds[0][2] << ") to ("
              << s.bounds[1][0] << ", " << s.bounds[1][1] << ", " << s.bounds[1][2] << ")\n";
    std::cout << "  median cell size " << s.medianCellSize << "; default --voxel-size " << s.defaultVoxelSize << " ("
              << s.voxelSizeRule << ")\n";
    for (const auto& a : s.arrays)
        std::cout << "  array " << a.name << ": " << a.components << " component(s) on the " << (a.cellData ? "cells" : "points")
                  << "\n";
    if (!s.times.empty()) {
        // Where the times come from (OpenFOAM: the processor directories or the top level): once
        // when all come from one place, else after each.
        const bool sources = s.timeSources.size() == s.times.size();
        const bool oneSource = sources && std::all_of(s.timeSources.begin(), s.timeSources.end(),
                                                      [&](const std::string& x) { return x == s.timeSources.front(); });
        std::cout << "  " << s.times.size() << " time steps" << (oneSource ? ", from " + s.timeSources.front() : "") << ":";
        for (std::size_t i = 0; i < s.times.size(); ++i)
            std::cout << (sources && !oneSource ? "\n   " : "") << " [" << i << "] " << s.times[i]
                      << (sources && !oneSource ? " from " + s.timeSources[i] : "");
        std::cout << "\n  (read: time " << (s.time ? *s.time : s.times.back()) << ")\n";
    }
    for (const auto& w : s.warnings) std::cout << "  warning: " << w << "\n";
    return 0;
}

int ConvertCommand::run(Context&)
{
    FieldSpec base = spec();
    const std::string format = resolveInputFormat(mInput, base.format);
    if (mList) return list(format);
    if (mOut.empty()) throw lic::InputError("--out is required (or --list to describe the input)");
    const std::vector<double> times = chooseTimes(format);
    const bool series = !times.empty() && isFramePattern(mOut);
    const std::vector<double> all = series ? meshTimes(mInput, format) : std::vector<double>{};

    json summary{{"input", mInput}, {"files", json::array()}, {"notes", json::array()}, {"warnings", json::array()}};
    summary = runWithProgress(mCommon.quiet, mCommon.progressStyle(), [&](lic::Progress& progress) {
        OutputSet outputs; // every file appears together, or none
        const std::size_t steps = times.empty() ? 1 : times.size();
        for (std::size_t k = 0; k < steps; ++k) {
            FieldSpec s = base;
            if (!times.empty()) s.time = times[k];
            LoadedField f = loadField(s, progress);
            for (const auto& n : f.notes) summary["notes"].push_back(n);
            for (const auto& w : f.warnings) summary["warnings"].push_back(w);
            f.velocity->setName("velocity");
            if (!f.velocity->getMetadata<openvdb::StringMetadata>("source_array"))
                f.velocity->insertMeta("source_array", openvdb::StringMetadata(f.gridName));
            openvdb::GridPtrVec grids{f.velocity};
            for (const auto& [name, g] : f.scalars)
                if (name != "velocity") grids.push_back(g);
            // The step's index among the series' times names the file.
            const std::size_t index = series ? std::size_t(std::find(all.begin(), all.end(), times[k]) - all.begin()) : k;
            const std::string path = series ? expandFramePattern(mOut, int(index)) : mOut;
            outputs.addVdb(path, grids);
            json file{{"path", path}, {"grids", json::array()}, {"active_voxels", f.velocity->activeVoxelCount()},
                      {"voxel_size", f.velocity->voxelSize()[0]}};
            if (s.time) file["time"] = *s.time;
            for (const auto& g : grids) file["grids"].push_back(g->getName());
            summary["files"].push_back(file);
        }
        outputs.commit();
        return summary;
    });
    // Warnings (a velocity zero or uniform everywhere, a case with only initial conditions): the
    // files are written, and the warnings go to stderr even with --quiet or --json (bake refuses
    // such a field).
    if (mCommon.json) std::cout << summary.dump(2) << "\n";
    if (!mCommon.json && !mCommon.quiet)
        for (const auto& n : summary["notes"]) std::cerr << "licvdb convert: " << n.get<std::string>() << "\n";
    for (const auto& w : summary["warnings"]) std::cerr << "licvdb convert: warning: " << w.get<std::string>() << "\n";
    if (!mCommon.json && !mCommon.quiet) {
        for (const auto& f : summary["files"])
            std::cerr << "wrote " << f["path"].get<std::string>() << " (" << f["active_voxels"].get<std::uint64_t>()
                      << " active voxels" << (f.contains("time") ? ", time " + f["time"].dump() : "") << ")\n";
    }
    return 0;
}

} // namespace

std::unique_ptr<Command> makeConvertCommand() { return std::make_unique<ConvertCommand>(); }

} // namespace vdbexport::cli

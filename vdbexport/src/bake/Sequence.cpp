// An unsteady bake: one output frame per field frame, the input texture carried by the flow from
// frame to frame (lic/texture/Advection.h), each frame convolved along its own field. The frames are
// staged as they are made and committed with one manifest at the end: a failed, cancelled or
// killed sequence leaves nothing.
#include "Sequence.h"

#include "Composite.h"
#include "Distribute.h"
#include "FieldShare.h"
#include "Input.h"
#include "Plan.h"
#include "Scalars.h"
#include "Write.h"

#include "vdbexport/bake/Bake.h"
#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/io/VdbIO.h"

#include "lic/composite/Colormap.h"
#include "lic/engine/Engine.h"
#include "lic/util/Error.h"
#include "lic/field/Region.h"
#include "lic/texture/Advection.h"

#include <openvdb/openvdb.h>

#include <sys/resource.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>

namespace vdbexport::pipeline {

namespace fs = std::filesystem;

namespace {

/// Stage names of one frame shown as "frame 12 (3/40): fast LIC".
class FrameProgress : public lic::Progress
{
public:
    FrameProgress(lic::Progress& inner) : mInner(inner) {}
    void setFrame(int number, int index, int count)
    {
        mPrefix = "frame " + std::to_string(number) + " (" + std::to_string(index) + "/" + std::to_string(count) + "): ";
    }
    void begin(const std::string& stage, std::uint64_t total) override { mInner.begin(mPrefix + stage, total); }
    void advance(std::uint64_t units) override { mInner.advance(units); }
    void end() override { mInner.end(); }
    bool wasInterrupted() override { return mInner.wasInterrupted(); }

private:
    lic::Progress& mInner;
    std::string mPrefix;
};

/// World units per second of one unit of the field's velocity. 1, except for a Blender mantaflow
/// cache (a staggered `velocity` with mantaflow's `file_base_resolution` metadata), which stores
/// cells per mantaflow time unit, 0.1·25/fps seconds of a frame (Blender's default dt 0.1 at 25
/// fps, time scale 1): world units per second = value × voxel size × 2.5 (measured, docs/inputs.md).
double worldPerSecond(const openvdb::Vec3SGrid& velocity, std::string& unit)
{
    const bool mantaflow = velocity.getGridClass() == openvdb::GRID_STAGGERED && velocity["file_base_resolution"];
    if (!mantaflow) {
        unit = "world units per second";
        return 1.0;
    }
    unit = "mantaflow cells per 0.1 s at 25 fps (converted: x voxel size x 2.5)";
    return velocity.voxelSize()[0] * 2.5;
}

void raiseFileLimit(std::size_t files)
{
    rlimit lim{};
    if (getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
    const rlim_t want = rlim_t(files + 64);
    if (lim.rlim_cur >= want) return;
    lim.rlim_cur = std::min(lim.rlim_max, want);
    setrlimit(RLIMIT_NOFILE, &lim);
}

} // namespace

nlohmann::json bakeSequence(const Recipe& request, lic::Progress& outer)
{
    using Clock = std::chrono::steady_clock;
    auto seconds = [](Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); };
    const auto t0 = Clock::now();
    Recipe recipe = request;
    if (recipe.lic.engine == "auto") recipe.lic.engine = recipe.input.type == "spots" ? "splat" : "fast";
    recipe.validate();
    recipe.validatePaths();
    if (recipe.animation.frames > 1) {
        throw lic::InputError("animation.frames: must be 1 with an unsteady field sequence (" + recipe.field.path +
                              "): a sequence plays once, it is not a loop (got " + std::to_string(recipe.animation.frames) + ")");
    }
    if (Job::current().distributed()) {
        throw lic::InputError("an unsteady sequence (field.frames) runs as one process: run it without mpirun "
                              "(its frames depend on each other; distributing them is not supported yet)");
    }
    if (recipe.input.surface) {
        throw lic::InputError("input.surface: spots on a ridge surface are not carried through an unsteady sequence "
                              "(the surface moves with the flow); use spots that fill the volume, or bake frames one by one");
    }
    const FieldFrames frames = resolveFieldFrames(recipe.field);
    const int count = int(frames.numbers.size());
    // No output frame may be one of the input frames under any name (as fs::equivalent: the same
    // device and inode; each frame's plan checks only its own pair).
    std::set<std::pair<dev_t, ino_t>> inputs;
    for (const std::string& in : frames.paths) {
        struct stat st{};
        if (::stat(in.c_str(), &st) == 0) inputs.insert({st.st_dev, st.st_ino});
    }
    for (int number : frames.numbers) {
        const std::string out = sequenceFramePath(recipe.output.path, number);
        struct stat st{};
        if (::stat(out.c_str(), &st) == 0 && inputs.count({st.st_dev, st.st_ino})) {
            throw lic::InputError("the bake would overwrite an input field frame with \"" + out + "\"; choose another --out");
        }
    }
    raiseFileLimit(std::size_t(count) + 1);
    openvdb::initialize();
    FrameProgress progress(outer);

    const nlohmann::json resolved = recipe.toJson();
    auto output = std::make_shared<OutputSet>();
    lic::AdvectedNoise noise(recipe.input.seed);
    std::optional<lic::SpotFlock> flock;
    Ranges ranges;
    std::optional<lic::Colormap> cmap;
    openvdb::math::Transform::Ptr transform0;
    std::string grid0, velocityUnit;
    std::vector<std::string> paths;
    nlohmann::json perFrame = nlohmann::json::array(), firstGrids, spotsJson = nullptr, colorJson = nullptr;
    double sumRead = 0, sumInput = 0, sumConvolve = 0, sumCompose = 0, sumWrite = 0;

    for (int k = 0; k < count; ++k) {
        const int number = frames.numbers[std::size_t(k)];
        progress.setFrame(number, k + 1, count);
        if (progress.wasInterrupted()) throw lic::Cancelled();
        const auto tf = Clock::now();
        Recipe fr = recipe;
        fr.field.path = frames.paths[std::size_t(k)];
        fr.field.frames.reset();
        fr.output.path = sequenceFramePath(recipe.output.path, number);
        const Plan plan = makePlan(fr);

        // Field: the frame's own; one transform and grid for the whole sequence.
        FieldShare share = readFieldShare(plan, 0, 1);
        const LoadedField& loaded = share.loaded;
        const lic::VelocityField& field = *share.field;
        const lic::OutputDomain& domain = *share.domain;
        const lic::BrickLayout& layout = *share.layout;
        const double toWorld = worldPerSecond(*loaded.velocity, velocityUnit);
        if (k == 0) {
            transform0 = loaded.velocity->transform().copy();
            grid0 = loaded.gridName;
        } else {
            if (loaded.gridName != grid0) {
                throw lic::InputError("field sequence: frame " + std::to_string(number) + " (\"" + fr.field.path +
                                      "\") has velocity grid \"" + loaded.gridName + "\", frame " +
                                      std::to_string(frames.numbers[0]) + " has \"" + grid0 + "\"");
            }
            if (loaded.velocity->transform() != *transform0) {
                std::ostringstream msg;
                msg << "field sequence: frame " << number << " (\"" << fr.field.path
                    << "\") has another transform than frame " << frames.numbers[0] << " (voxel size "
                    << loaded.velocity->voxelSize() << " vs " << transform0->voxelSize()
                    << "); every frame of a sequence must share one grid transform";
                throw lic::InputError(msg.str());
            }
        }
        const double tRead = seconds(tf);

        // Scalars; automatic ranges from the first frame, kept for all (colours do not flicker).
        ScalarSet scalars(*loaded.velocity, loaded.scalars);
        if (k == 0) ranges = bakeRanges(recipe, scalars, domain, cmap);

        // Input: frame one as a still bake; later frames carried from the previous one.
        const auto ti = Clock::now();
        const double dt = toWorld / recipe.field.fps;
        Input input;
        nlohmann::json carried;
        if (plan.spots) {
            if (k == 0) {
                input = makeInput(plan, domain, scalars);
                lic::SpotFlock::Params params;
                params.placement = {lic::spotDistributionFromString(recipe.input.distribution), recipe.input.spacing,
                                    recipe.input.jitter, recipe.input.seed};
                flock.emplace(params);
                flock->start(input.spots);
            } else {
                lic::SpotFlock::Accept accept;
                std::optional<ScalarField> roi;
                if (plan.roiPre) {
                    roi.emplace(scalars.get(recipe.roi->scalar));
                    accept = [&](const openvdb::Vec3d& c) {
                        return lic::roiWeight(roi->at(domain.map().toWorld(c)), recipe.roi->range[0], recipe.roi->range[1]);
                    };
                }
                flock->advance(domain, field, dt, k + 1, accept);
                input.spots = flock->current();
            }
            input.spotCount = input.spots.centers.size();
            const lic::SpotFlock::Stats& moved = flock->stats();
            carried = {{"spots", input.spotCount}, {"born", moved.born}, {"left", moved.left}, {"retiring", moved.retiring}};
        } else {
            if (k == 0) noise.start(domain);
            else noise.advance(domain, field, dt);
            input = makeInput(plan, domain, scalars, nullptr, noise.rawNoise());
            const auto& ns = noise.stats();
            carried = {{"voxels", ns.voxels}, {"carried", ns.carried}, {"entered", ns.entered}, {"refreshed", ns.refreshed}};
        }
        const double tInput = seconds(ti);

        // Convolve along this frame's flow and composite.
        std::optional<Compositor> compositor;
        compositor.emplace(plan, field, domain, layout, scalars, input, cmap ? &*cmap : nullptr, ranges);
        const lic::BrickSink sink = [&](const lic::BrickChannels& b) { compositor->consume(b); };
        const lic::LicStats st =
            plan.spots ? lic::convolveSpotBricks(field, domain, layout, input.spots, recipe.input.radii, recipe.input.haloScale,
                                                 plan.settings, progress, sink)
                       : lic::convolveNoiseBricks(field, domain, layout, *input.noise, plan.settings, progress, sink);
        const auto tc = Clock::now();
        compositor->finish();
        const double tCompose = seconds(tc);

        // Stage the frame.
        const auto tw = Clock::now();
        Description desc = describeBake(plan, resolved, loaded.gridName, layout.dim(), input.spotCount, ranges,
                                        cmap ? &*cmap : nullptr);
        desc.densityMeta.insertMeta("lic_frames", openvdb::Int32Metadata(count));
        desc.densityMeta.insertMeta("lic_cyclic", openvdb::BoolMetadata(false));
        desc.densityMeta.insertMeta("lic_unsteady", openvdb::BoolMetadata(true));
        desc.densityMeta.insertMeta("lic_first_frame", openvdb::Int32Metadata(frames.numbers.front()));
        desc.densityMeta.insertMeta("lic_fps", openvdb::DoubleMetadata(recipe.field.fps));
        desc.densityMeta.insertMeta("licvdb_field_file", openvdb::StringMetadata(fs::path(fr.field.path).filename().string()));
        progress.begin("writing", 1);
        openvdb::GridPtrVec grids = compositor->frame(1);
        stageFrame(fr, grids, desc.densityMeta, number, fr.output.path, *output);
        progress.advance(1);
        progress.end();
        paths.push_back(fr.output.path);
        if (k == 0) {
            firstGrids = gridsJson(grids);
            spotsJson = desc.spots;
            colorJson = desc.color;
        }
        const double tWrite = seconds(tw);
        sumRead += tRead, sumInput += tInput, sumConvolve += st.seconds, sumCompose += tCompose, sumWrite += tWrite;
        const lic::ChannelStats& raw = compositor->rawStats();
        perFrame.push_back({{"frame", number},
                            {"file", fs::path(fr.output.path).filename().string()},
                            {"output_voxels", st.voxels},
                            {"density_active_voxels", grids.front()->activeVoxelCount()},
                            {"raw_mean", raw.mean},
                            {"texture", carried},
                            {"seconds", {{"read", tRead}, {"input", tInput}, {"convolve", st.seconds},
                                         {"compose", tCompose}, {"write", tWrite}, {"total", seconds(tf)}}}});
    }

    // One manifest for the sequence, then every file at once.
    if (outer.wasInterrupted()) throw lic::Cancelled();
    nlohmann::json fieldFiles = nlohmann::json::array();
    for (const auto& p : frames.paths) fieldFiles.push_back(fs::path(p).filename().string());
    writeManifest(recipe, resolved, paths, *output, firstGrids, transform0->voxelSize()[0] / double(recipe.output.upsample),
                  colorJson, spotsJson,
                  {{"cyclic", false}, {"unsteady", true}, {"first_frame", frames.numbers.front()},
                   {"fps", recipe.field.fps}, {"velocity_unit", velocityUnit}, {"field_files", fieldFiles}});

    const double total = seconds(t0);
    return {{"output", recipe.output.path},
            {"files", paths},
            {"frames", count},
            {"first_frame", frames.numbers.front()},
            {"unsteady", true},
            {"fps", recipe.field.fps},
            {"velocity_unit", velocityUnit},
            {"manifest", manifestPath(recipe.output.path)},
            {"field", {{"pattern", recipe.field.path}, {"grid", grid0}, {"files", frames.paths}}},
            {"engine", recipe.lic.engine},
            {"per_frame", perFrame},
            {"seconds", {{"read", sumRead}, {"input", sumInput}, {"convolve", sumConvolve}, {"compose", sumCompose},
                         {"write", sumWrite}, {"total", total}, {"per_frame", total / double(count)}}}};
}

} // namespace vdbexport::pipeline

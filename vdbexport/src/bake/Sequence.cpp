// An unsteady bake: one output frame per field frame, the input texture carried by the flow from
// frame to frame (lic/texture/Advection.h), each frame baked along its own field by the one frame
// bake (bake/Frame.h). The frames are staged as they are made and committed with one manifest at
// the end: a failed, cancelled or killed sequence leaves nothing.
#include "bake/Sequence.h"

#include "bake/Distribute.h"
#include "bake/Frame.h"
#include "bake/Plan.h"
#include "bake/Write.h"

#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/io/OutputNames.h"
#include "vdbexport/io/VdbIO.h"

#include "lic/engine/Engine.h"
#include "lic/field/Region.h"
#include "lic/texture/Advection.h"
#include "lic/util/Error.h"

#include <openvdb/openvdb.h>

#include <sys/resource.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <optional>
#include <set>
#include <sstream>

namespace vdbexport::pipeline {

namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

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

/// What a sequence refuses before reading any frame, and the frames it bakes.
/// @throw lic::InputError naming the problem.
FieldFrames checkSequence(const Recipe& recipe)
{
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
    FieldFrames frames = resolveFieldFrames(recipe.field);
    // No output frame may be one of the input frames under any name (as fs::equivalent: the same
    // device and inode; each frame's plan checks only its own pair).
    std::set<std::pair<dev_t, ino_t>> inputs;
    for (const std::string& in : frames.paths) {
        struct stat st{};
        if (::stat(in.c_str(), &st) == 0) inputs.insert({st.st_dev, st.st_ino});
    }
    for (int number : frames.numbers) {
        const std::string out = numberedPath(recipe.output.path, number);
        struct stat st{};
        if (::stat(out.c_str(), &st) == 0 && inputs.count({st.st_dev, st.st_ino})) {
            throw lic::InputError("the bake would overwrite an input field frame with \"" + out + "\"; choose another --out");
        }
    }
    return frames;
}

/// The texture carried from frame to frame: noise advected (Lagrangian–Eulerian) or a flock of
/// spots moving with the flow. Frame one is made as a still bake's.
class CarriedTexture
{
public:
    explicit CarriedTexture(const Recipe& recipe) : mRecipe(recipe), mNoise(recipe.input.seed) {}

    /// The input of frame index k (0-based), `dt` seconds after the previous frame.
    Input next(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars);
    /// Counters of the last step, for the frame's summary.
    const nlohmann::json& counters() const { return mCounters; }

private:
    Input spots(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars);

    const Recipe& mRecipe;
    lic::AdvectedNoise mNoise;
    std::optional<lic::SpotFlock> mFlock;
    nlohmann::json mCounters;
};

Input CarriedTexture::next(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars)
{
    if (plan.spots) return spots(k, dt, plan, share, scalars);
    const lic::OutputDomain& domain = *share.domain;
    if (k == 0) mNoise.start(domain);
    else mNoise.advance(domain, *share.field, dt);
    Input input = makeInput(plan, domain, scalars, nullptr, mNoise.rawNoise());
    const auto& ns = mNoise.stats();
    mCounters = {{"voxels", ns.voxels}, {"carried", ns.carried}, {"entered", ns.entered}, {"refreshed", ns.refreshed}};
    return input;
}

Input CarriedTexture::spots(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars)
{
    const lic::OutputDomain& domain = *share.domain;
    Input input;
    if (k == 0) {
        input = makeInput(plan, domain, scalars);
        lic::SpotFlock::Params params;
        params.placement = {lic::spotDistributionFromString(mRecipe.input.distribution), mRecipe.input.spacing,
                            mRecipe.input.jitter, mRecipe.input.seed};
        mFlock.emplace(params);
        mFlock->start(input.spots);
    } else {
        lic::SpotFlock::Accept accept;
        std::optional<lic::ScalarField> roi;
        if (plan.roiPre) {
            roi.emplace(scalars.get(mRecipe.roi->scalar));
            accept = [&](const openvdb::Vec3d& c) {
                return lic::roiWeight(roi->at(domain.map().toWorld(c)), mRecipe.roi->range[0], mRecipe.roi->range[1]);
            };
        }
        mFlock->advance(domain, *share.field, dt, k + 1, accept);
        input.spots = mFlock->current();
    }
    input.spotCount = input.spots.centers.size();
    const lic::SpotFlock::Stats& moved = mFlock->stats();
    mCounters = {{"spots", input.spotCount}, {"born", moved.born}, {"left", moved.left}, {"retiring", moved.retiring}};
    return input;
}

/// Frame `number` must share the first frame's velocity grid and transform.
void checkSameGrid(const FieldShare& share, const std::string& path, int number, int firstNumber,
                   const openvdb::math::Transform& transform0, const std::string& grid0)
{
    const LoadedField& loaded = share.loaded;
    if (loaded.gridName != grid0) {
        throw lic::InputError("field sequence: frame " + std::to_string(number) + " (\"" + path + "\") has velocity grid \"" +
                              loaded.gridName + "\", frame " + std::to_string(firstNumber) + " has \"" + grid0 + "\"");
    }
    if (loaded.velocity->transform() != transform0) {
        std::ostringstream msg;
        msg << "field sequence: frame " << number << " (\"" << path << "\") has another transform than frame "
            << firstNumber << " (voxel size " << loaded.velocity->voxelSize() << " vs " << transform0.voxelSize()
            << "); every frame of a sequence must share one grid transform";
        throw lic::InputError(msg.str());
    }
}

/// What the sequence keeps from frame to frame.
struct SequenceState
{
    SequenceState(const Recipe& r, const FieldFrames& f) : recipe(r), frames(f), resolved(r.toJson()), texture(r) {}

    const Recipe& recipe;
    const FieldFrames& frames;
    const nlohmann::json resolved;
    OutputSet output;
    CarriedTexture texture;
    Ranges ranges;
    openvdb::math::Transform::Ptr transform0;
    std::string grid0, velocityUnit;
    std::vector<std::string> paths;
    nlohmann::json perFrame = nlohmann::json::array(), firstGrids, spotsJson = nullptr, colorJson = nullptr;
    double sumRead = 0, sumInput = 0, sumConvolve = 0, sumCompose = 0, sumWrite = 0;
};

/// Bake frame index k of the sequence and stage its file.
void bakeFrame(SequenceState& seq, int k, FrameProgress& progress)
{
    const Recipe& recipe = seq.recipe;
    const int number = seq.frames.numbers[std::size_t(k)], count = int(seq.frames.numbers.size());
    progress.setFrame(number, k + 1, count);
    if (progress.wasInterrupted()) throw lic::Cancelled();
    const auto tf = Clock::now();
    Recipe fr = recipe;
    fr.field.path = seq.frames.paths[std::size_t(k)];
    fr.field.frames.reset();
    fr.output.path = numberedPath(recipe.output.path, number);
    const Plan plan = makePlan(fr);

    FrameOptions options;
    if (k > 0) options.ranges = &seq.ranges; // automatic ranges from the first frame, kept for all
    options.onField = [&](const FieldShare& share) {
        if (k == 0) {
            seq.transform0 = share.loaded.velocity->transform().copy();
            seq.grid0 = share.loaded.gridName;
        } else {
            checkSameGrid(share, fr.field.path, number, seq.frames.numbers[0], *seq.transform0, seq.grid0);
        }
    };
    options.input = [&](const Plan& p, const FieldShare& share, lic::ScalarSet& scalars) {
        const double dt = worldPerSecond(*share.loaded.velocity, seq.velocityUnit) / recipe.field.fps;
        return seq.texture.next(k, dt, p, share, scalars);
    };
    options.velocityScale = [&](const FieldShare& share) {
        return worldPerSecond(*share.loaded.velocity, seq.velocityUnit);
    };
    FrameBake fb(plan, Job::current(), progress, std::move(options));
    if (k == 0) seq.ranges = fb.ranges;

    // Stage the frame.
    const auto tw = Clock::now();
    Description desc = describeBake(plan, seq.resolved, fb.share.loaded.gridName, fb.layout().dim(), fb.spotCount,
                                    seq.ranges, fb.cmap ? &*fb.cmap : nullptr);
    desc.densityMeta.insertMeta("lic_frames", openvdb::Int32Metadata(count));
    desc.densityMeta.insertMeta("lic_cyclic", openvdb::BoolMetadata(false));
    desc.densityMeta.insertMeta("lic_unsteady", openvdb::BoolMetadata(true));
    desc.densityMeta.insertMeta("lic_first_frame", openvdb::Int32Metadata(seq.frames.numbers.front()));
    desc.densityMeta.insertMeta("lic_fps", openvdb::DoubleMetadata(recipe.field.fps));
    desc.densityMeta.insertMeta("licvdb_field_file", openvdb::StringMetadata(fs::path(fr.field.path).filename().string()));
    progress.begin("writing", 1);
    openvdb::GridPtrVec grids = fb.compositor->frame(1);
    stageFrame(fr, grids, desc.densityMeta, number, fr.output.path, seq.output);
    progress.advance(1);
    progress.end();
    seq.paths.push_back(fr.output.path);
    if (k == 0) {
        seq.firstGrids = gridsJson(grids);
        seq.spotsJson = desc.spots;
        seq.colorJson = desc.color;
    }
    const double tWrite = since(tw);
    const FrameBake::Times& t = fb.seconds;
    seq.sumRead += t.read, seq.sumInput += t.input, seq.sumConvolve += t.convolve, seq.sumCompose += t.compose,
        seq.sumWrite += tWrite;
    seq.perFrame.push_back({{"frame", number},
                            {"file", fs::path(fr.output.path).filename().string()},
                            {"output_voxels", fb.stats.voxels},
                            {"density_active_voxels", grids.front()->activeVoxelCount()},
                            {"raw_mean", fb.compositor->rawStats().mean},
                            {"texture", seq.texture.counters()},
                            {"seconds", {{"read", t.read}, {"input", t.input}, {"convolve", t.convolve},
                                         {"compose", t.compose}, {"write", tWrite}, {"total", since(tf)}}}});
}

} // namespace

nlohmann::json bakeSequence(const Recipe& request, lic::Progress& outer)
{
    const auto t0 = Clock::now();
    Recipe recipe = request;
    if (recipe.lic.engine == "auto") recipe.lic.engine = lic::toString(lic::chooseEngine("auto", recipe.input.type == "spots"));
    const FieldFrames frames = checkSequence(recipe);
    const int count = int(frames.numbers.size());
    raiseFileLimit(std::size_t(count) + 1);
    openvdb::initialize();
    FrameProgress progress(outer);
    SequenceState seq(recipe, frames);
    for (int k = 0; k < count; ++k) bakeFrame(seq, k, progress);

    // One manifest for the sequence, then every file at once.
    if (outer.wasInterrupted()) throw lic::Cancelled();
    nlohmann::json fieldFiles = nlohmann::json::array();
    for (const auto& p : frames.paths) fieldFiles.push_back(fs::path(p).filename().string());
    writeManifest(recipe, seq.resolved, seq.paths, seq.output, seq.firstGrids,
                  seq.transform0->voxelSize()[0] / double(recipe.output.upsample), seq.colorJson, seq.spotsJson,
                  {{"cyclic", false}, {"unsteady", true}, {"first_frame", frames.numbers.front()},
                   {"fps", recipe.field.fps}, {"velocity_unit", seq.velocityUnit}, {"field_files", fieldFiles}});

    const double total = since(t0);
    return {{"output", recipe.output.path},
            {"files", seq.paths},
            {"frames", count},
            {"first_frame", frames.numbers.front()},
            {"unsteady", true},
            {"fps", recipe.field.fps},
            {"velocity_unit", seq.velocityUnit},
            {"manifest", manifestPath(recipe.output.path)},
            {"field", {{"pattern", recipe.field.path}, {"grid", seq.grid0}, {"files", frames.paths}}},
            {"engine", recipe.lic.engine},
            {"per_frame", seq.perFrame},
            {"seconds", {{"read", seq.sumRead}, {"input", seq.sumInput}, {"convolve", seq.sumConvolve},
                         {"compose", seq.sumCompose}, {"write", seq.sumWrite}, {"total", total},
                         {"per_frame", total / double(count)}}}};
}

} // namespace vdbexport::pipeline

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
#include "vdbexport/io/SealedLeaves.h"
#include "vdbexport/io/OutputSet.h"

#include "lic/engine/Engine.h"
#include "lic/field/Region.h"
#include "lic/texture/Advection.h"
#include "lic/util/Error.h"

#include <openvdb/openvdb.h>

#include <sys/resource.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
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
    if (recipe.input.surface) {
        throw lic::InputError("input.surface: spots on a ridge surface are not carried through an unsteady sequence "
                              "(the surface moves with the flow); use spots that fill the volume, or bake frames one by one");
    }
    if (!recipe.input.seeds.empty()) {
        throw lic::InputError("input.seeds (--seeds) is not available with an unsteady field sequence yet: new spots "
                              "enter a sequence by input.distribution, not from the seeds file; use a distribution, "
                              "or bake the frames one by one with --seeds");
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

/// The blocks of `domain` with a voxel within `reach` voxels of the boxes of `bricks` (ids in
/// `layout`), ascending.
std::vector<std::uint32_t> blocksNearBricks(const lic::OutputDomain& domain, const lic::BrickLayout& layout,
                                            const std::vector<std::size_t>& bricks, int reach)
{
    std::vector<std::uint8_t> mark(domain.blockCount(), 0);
    for (std::size_t id : bricks) domain.markBlocks(layout[id].box.expandBy(reach), mark);
    return lic::OutputDomain::markedBlocks(mark);
}

/// The texture carried from frame to frame: noise advected (Lagrangian–Eulerian) or a flock of
/// spots moving with the flow. Frame one is made as a still bake's.
///
/// Distributed (docs/distributed.md): the spots (a few per spacing³) are held and moved by every
/// rank alike (each frame's field is read whole), and each rank keeps those that reach its
/// bricks. The noise state (16 bytes per output voxel) is held in parts: each rank keeps the
/// blocks its bricks and their ghost margins read; before advancing, it receives from the ranks
/// that owned them in the previous frame the blocks it reaches back to that it does not hold
/// (the previous frame's bricks' owners send; the margin is one block plus the frame's largest
/// displacement), so only the margins travel; the field is read in parts, their margin grown by
/// what the advance reaches.
class CarriedTexture
{
public:
    CarriedTexture(const Recipe& recipe, Job& job) : mRecipe(recipe), mJob(job), mNoise(recipe.input.seed) {}

    /// The input of frame index k (0-based), `dt` seconds after the previous frame.
    Input next(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars);
    /// Counters of the last step (the whole bake's), for the frame's summary.
    const nlohmann::json& counters() const { return mCounters; }
    /// Distributed noise: blocks of state held now, and bytes received from other ranks so far.
    std::size_t heldBlocks() const { return mHeldBlocks; }
    std::uint64_t receivedBytes() const { return mReceived; }

private:
    Input noise(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars);
    Input spots(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars);
    /// Distributed noise: receive the previous frame's blocks this rank's part of frame k reads.
    void importMargins(const FieldShare& share, double dt, const std::vector<std::vector<std::uint32_t>>& keep);

    const Recipe& mRecipe;
    Job& mJob;
    lic::AdvectedNoise mNoise;
    std::optional<lic::SpotFlock> mFlock;
    nlohmann::json mCounters;
    // Distributed noise: per rank, the blocks of the current frame it keeps (ascending); this
    // rank's own (a mark per block).
    std::vector<std::vector<std::uint32_t>> mKeep;
    std::vector<std::uint8_t> mOwn;
    std::size_t mHeldBlocks = 0;
    std::uint64_t mReceived = 0;
};

Input CarriedTexture::next(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars)
{
    return plan.spots ? spots(k, dt, plan, share, scalars) : noise(k, dt, plan, share, scalars);
}

void CarriedTexture::importMargins(const FieldShare& share, double dt, const std::vector<std::vector<std::uint32_t>>& keep)
{
    const lic::OutputDomain& prev = *mNoise.domain();
    const lic::OutputDomain& domain = *share.domain;
    // The frame's largest move in output voxels (√3: a staggered field's sampled velocity can
    // exceed the largest cell-centred speed by that factor, never more).
    const double displacement = std::sqrt(3.0) * share.field->maxSpeed() * std::abs(dt) / domain.voxelSize();
    std::vector<std::string> out(std::size_t(mJob.size()));
    for (int q = 0; q < mJob.size(); ++q) {
        if (q == mJob.rank()) continue;
        const std::vector<std::uint32_t>& had = mKeep[std::size_t(q)];
        std::vector<std::uint32_t> send;
        for (std::uint32_t b : lic::AdvectedNoise::sourceBlocks(prev, domain, keep[std::size_t(q)], displacement))
            if (mOwn[b] && !std::binary_search(had.begin(), had.end(), b)) send.push_back(b);
        out[std::size_t(q)] = mNoise.pack(send);
    }
    const std::vector<std::string> in = mJob.exchange(std::move(out), "exchanging the texture's margins");
    for (int r = 0; r < mJob.size(); ++r) {
        if (r == mJob.rank()) continue;
        mReceived += in[std::size_t(r)].size();
        mNoise.unpack(in[std::size_t(r)]);
    }
}

Input CarriedTexture::noise(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars)
{
    const lic::OutputDomain& domain = *share.domain;
    std::optional<lic::AdvectedNoise::Part> part;
    std::vector<std::vector<std::uint32_t>> keep;
    if (mJob.distributed()) {
        // Every rank's part of this frame: the blocks its bricks' noise reads (the ghost margin and
        // the filter's two voxels), and its own blocks.
        const int reach = lic::ghostMargin(plan.settings) + 2;
        for (int q = 0; q < mJob.size(); ++q)
            keep.push_back(blocksNearBricks(domain, *share.layout, bricksOf(share.assignment, q), reach));
        part.emplace();
        part->keep = keep[std::size_t(mJob.rank())];
        for (std::size_t id : share.mine)
            part->own.insert(part->own.end(), (*share.layout)[id].blocks.begin(), (*share.layout)[id].blocks.end());
        std::sort(part->own.begin(), part->own.end());
    }
    const lic::AdvectedNoise::Part* p = part ? &*part : nullptr;
    if (k == 0) {
        mNoise.start(domain, p);
    } else {
        if (p) importMargins(share, dt, keep);
        mNoise.advance(domain, *share.field, dt, p);
    }
    if (p) {
        mKeep = std::move(keep);
        mOwn.assign(domain.blockCount(), 0);
        for (std::uint32_t b : p->own) mOwn[b] = 1;
        mHeldBlocks = p->keep.size();
    }
    Input input = makeInput(plan, domain, scalars, nullptr, mNoise.rawNoise());
    const auto& ns = mNoise.stats();
    std::vector<std::uint64_t> c = {ns.voxels, ns.carried, ns.entered, ns.refreshed};
    mJob.sumAll(c, "making the input texture");
    mCounters = {{"voxels", c[0]}, {"carried", c[1]}, {"entered", c[2]}, {"refreshed", c[3]}};
    return input;
}

Input CarriedTexture::spots(int k, double dt, const Plan& plan, const FieldShare& share, lic::ScalarSet& scalars)
{
    // Every rank holds and moves the whole flock (the field is read whole), then keeps the spots
    // that reach its bricks, as a still distributed bake does.
    const lic::OutputDomain& domain = *share.domain;
    Input input;
    if (k == 0) {
        input = makeInput(plan, domain, scalars);
        lic::SpotFlock::Params params;
        params.placement = {lic::spotDistributionFromString(mRecipe.input.distribution), mRecipe.input.spacing,
                            mRecipe.input.jitter, mRecipe.input.seed};
        mFlock.emplace(params);
        mFlock->start(input.spots, domain);
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
    const std::size_t total = input.spots.centers.size();
    input.spotCount = total;
    if (mJob.distributed()) input.spots = spotsOfShare(input.spots, domain, spotShareOf(plan, share), input.spotCount);
    const lic::SpotFlock::Stats& moved = mFlock->stats();
    mCounters = {{"spots", total}, {"born", moved.born}, {"left", moved.left}, {"retiring", moved.retiring}};
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
    SequenceState(const Recipe& r, const FieldFrames& f, Job& j)
        : recipe(r), frames(f), job(j), resolved(r.toJson()), texture(r, j)
    {
    }

    const Recipe& recipe;
    const FieldFrames& frames;
    Job& job;
    const nlohmann::json resolved;
    OutputSet output;
    CarriedTexture texture;
    Ranges ranges;
    openvdb::math::Transform::Ptr transform0;
    std::string grid0, velocityUnit;
    std::vector<std::string> paths;
    nlohmann::json perFrame = nlohmann::json::array(), firstGrids, spotsJson = nullptr, colorJson = nullptr;
    double sumRead = 0, sumInput = 0, sumConvolve = 0, sumCompose = 0, sumWrite = 0, sumGather = 0;
    // Distributed: the part's extra margin (field voxels, the largest so far), the last frame's
    // read, the most field voxels held in one frame.
    int partMargin = 0;
    bool partial = false;
    std::string wholeReason;
    std::uint64_t fieldHeld = 0;
};

/// Stage frame `number`'s grids: in one process directly; distributed, rank 0 adds every other
/// rank's leaves first (each frame's grids are its own: nothing is skipped) and stages, and every
/// rank agrees on the outcome.
void stageGathered(SequenceState& seq, FrameBake& fb, const Recipe& fr, const openvdb::MetaMap& meta, int number,
                   openvdb::GridPtrVec& grids, const vdbexport::detail::SealedLeaves* sealed)
{
    Job& job = seq.job;
    const std::string composing = "composing frame " + std::to_string(number);
    if (!job.distributed()) {
        grids = fb.compositor->frame(1);
        stageFrame(fr, grids, meta, number, fr.output.path, seq.output, sealed);
        return;
    }
    if (job.root()) {
        try {
            job.injectFault(composing.c_str());
            grids = fb.compositor->frame(1);
            job.agree(nullptr, composing.c_str());
            const auto tg = Clock::now();
            job.gatherLeaves(grids, {});
            seq.sumGather += since(tg);
            job.injectFault(("writing frame " + std::to_string(number)).c_str());
            stageFrame(fr, grids, meta, number, fr.output.path, seq.output);
        } catch (...) {
            if (job.failed()) throw;
            job.agree(std::current_exception(), "writing");
        }
    } else {
        grids = job.stage(composing.c_str(), [&] { return fb.compositor->frame(1); });
        const auto tg = Clock::now();
        job.gatherLeaves(grids, {});
        seq.sumGather += since(tg);
    }
    job.agree(nullptr, "writing");
}

/// Bake frame index k of the sequence and stage its file.
void bakeFrame(SequenceState& seq, int k, FrameProgress& progress)
{
    const Recipe& recipe = seq.recipe;
    const int number = seq.frames.numbers[std::size_t(k)], count = int(seq.frames.numbers.size());
    progress.setFrame(number, k + 1, count);
    // Distributed, every rank leaves together when one was interrupted.
    seq.job.stage("starting a frame", [&] {
        if (progress.wasInterrupted()) throw lic::Cancelled();
    });
    const auto tf = Clock::now();
    Recipe fr = recipe;
    fr.field.path = seq.frames.paths[std::size_t(k)];
    fr.field.frames.reset();
    fr.output.path = numberedPath(recipe.output.path, number);
    const Plan plan = seq.job.stage("planning the bake", [&] { return makePlan(fr); });

    FrameOptions options;
    if (seq.job.distributed() && plan.spots) {
        options.wholeField = "an unsteady spot sequence moves every spot on every rank, so each frame is read whole";
    } else if (seq.job.distributed() && k > 0) {
        // The carried noise's advance reads the field around its kept blocks' neighbours (up to
        // 17 output voxels past the ghost margin: block rounding twice and the refresh test) and
        // half a frame's displacement further (the midpoint of its back-trace).
        options.partMarginGuess = seq.partMargin > 0 ? seq.partMargin + 1 : 0;
        options.partMargin = [&](const FieldShare& share, double maxSpeed) {
            std::string unit;
            const double dt = worldPerSecond(*share.loaded.velocity, unit) / recipe.field.fps;
            const double displacement = std::sqrt(3.0) * maxSpeed * std::abs(dt) / share.domain->voxelSize();
            return int(std::ceil((17.0 + 0.5 * displacement) / double(recipe.output.upsample))) + 1;
        };
    }
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
    // One process: a spot frame's leaves are sealed as its bricks finish (as a still's, Bake.cpp).
    std::optional<vdbexport::detail::SealedLeaves> sealer;
    if (!seq.job.distributed() && sealingAllowed()) sealer.emplace(fr.output.half);
    options.sealer = sealer ? &*sealer : nullptr;
    FrameBake fb(plan, seq.job, progress, std::move(options));
    if (k == 0) seq.ranges = fb.ranges;
    seq.partMargin = std::max(seq.partMargin, fb.partMargin);
    seq.partial = fb.share.partial;
    seq.wholeReason = fb.share.wholeReason;
    seq.fieldHeld = std::max(seq.fieldHeld, fb.share.voxelsHeld);

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
    openvdb::GridPtrVec grids;
    if (fb.sealed) sealer->flush();
    stageGathered(seq, fb, fr, desc.densityMeta, number, grids, fb.sealed ? &*sealer : nullptr);
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
                            {"sealed_leaves", fb.sealed},
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
    Job& job = Job::current();
    const FieldFrames frames = job.stage("planning the bake", [&] { return checkSequence(recipe); });
    const int count = int(frames.numbers.size());
    raiseFileLimit(std::size_t(count) + 1);
    openvdb::initialize();
    FrameProgress progress(outer);
    SequenceState seq(recipe, frames, job);
    // Distributed: rank 0 stages every frame; a job killed before the manifest leaves nothing.
    std::optional<WriteGuard> guard;
    if (job.distributed() && job.root()) {
        std::vector<std::string> paths;
        for (int number : frames.numbers) paths.push_back(numberedPath(recipe.output.path, number));
        guard.emplace(paths, manifestPath(recipe.output.path));
    }
    for (int k = 0; k < count; ++k) bakeFrame(seq, k, progress);

    // One manifest for the sequence, then every file at once.
    job.stage("writing", [&] {
        if (outer.wasInterrupted()) throw lic::Cancelled();
    });
    nlohmann::json fieldFiles = nlohmann::json::array();
    for (const auto& p : frames.paths) fieldFiles.push_back(fs::path(p).filename().string());
    auto manifest = [&] {
        writeManifest(recipe, seq.resolved, seq.paths, seq.output, seq.firstGrids,
                      seq.transform0->voxelSize()[0] / double(recipe.output.upsample), seq.colorJson, seq.spotsJson,
                      {{"cyclic", false}, {"unsteady", true}, {"first_frame", frames.numbers.front()},
                       {"fps", recipe.field.fps}, {"velocity_unit", seq.velocityUnit}, {"field_files", fieldFiles}});
    };
    if (!job.distributed()) {
        manifest();
    } else if (job.root()) {
        try {
            job.injectFault("writing the manifest");
            manifest();
            guard->disarm();
        } catch (...) {
            if (job.failed()) throw;
            job.agree(std::current_exception(), "writing");
        }
    }
    job.agree(nullptr, "writing");

    const double total = since(t0);
    nlohmann::json summary = {
        {"output", recipe.output.path},
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
    if (job.distributed()) {
        const nlohmann::json mine = {{"rank", job.rank()},
                                     {"texture_blocks_held", seq.texture.heldBlocks()},
                                     {"texture_bytes_received", seq.texture.receivedBytes()},
                                     {"field_voxels_held", seq.fieldHeld},
                                     {"gather_seconds", seq.sumGather},
                                     {"peak_rss_mib", peakRssMiB()},
                                     {"cpu_seconds", cpuSeconds()}};
        nlohmann::json ranks = nlohmann::json::array();
        for (const std::string& text : job.allGather(mine.dump(), "summarising")) ranks.push_back(nlohmann::json::parse(text));
        summary["mpi"] = {{"ranks", job.size()},
                          {"partial_read", seq.partial},
                          {"whole_read_reason", seq.partial ? nlohmann::json(nullptr) : nlohmann::json(seq.wholeReason)},
                          {"assignment", "each frame's bricks in contiguous Morton runs, balanced by active voxels"}};
        summary["ranks"] = ranks;
    }
    return summary;
}

} // namespace vdbexport::pipeline

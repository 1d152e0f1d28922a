#include "bake/Frame.h"

#include "vdbexport/io/ColormapFile.h"

#include "lic/engine/Engine.h"
#include "lic/engine/Kernels.h"
#include "lic/util/Error.h"

#include <openvdb/openvdb.h>

#include <chrono>
#include <cstdlib>
#include <string>

namespace vdbexport::pipeline {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

/// A rank's progress through its share, shown as progress through the whole bake (the share
/// of `part` units out of `whole` moves the bar from 0 to 1).
class ShareProgress : public lic::Progress
{
public:
    ShareProgress(lic::Progress& inner, std::uint64_t part, std::uint64_t whole)
        : mInner(inner), mScale(part ? double(whole) / double(part) : 1.0)
    {
    }
    void begin(const std::string& stage, std::uint64_t total) override { mInner.begin(stage, total); }
    void advance(std::uint64_t units) override { mInner.advance(std::uint64_t(double(units) * mScale + 0.5)); }
    void end() override { mInner.end(); }
    bool wasInterrupted() override { return mInner.wasInterrupted(); }

private:
    lic::Progress& mInner;
    double mScale;
};

/// Output-index box of some bricks, grown by `pad` voxels (an inverted, empty box for none).
openvdb::BBoxd bricksBox(const lic::BrickLayout& layout, const std::vector<std::size_t>& ids, double pad)
{
    if (ids.empty()) return openvdb::BBoxd(openvdb::Vec3d(1.0), openvdb::Vec3d(0.0));
    openvdb::CoordBBox box;
    for (std::size_t id : ids) box.expand(layout[id].box);
    return openvdb::BBoxd(box.min().asVec3d() - openvdb::Vec3d(pad), box.max().asVec3d() + openvdb::Vec3d(pad));
}

/// The scalars and textures the compositor reads, for this plan.
lic::CompositeInputs compositeInputs(const Plan& plan, lic::ScalarSet& scalars, Input& input, const lic::Colormap* cmap)
{
    const Recipe& r = plan.recipe;
    lic::CompositeInputs in;
    if (r.width) in.width = lic::ScalarField(scalars.get(r.width->scalar));
    if (plan.roiPost) in.roi = lic::ScalarField(scalars.get(r.roi->scalar));
    if (r.color) in.color = lic::ScalarField(scalars.get(r.color->scalar));
    in.colormap = cmap;
    if (r.output.writes(lic::OutputGrid::Input)) {
        if (plan.spots) in.spots = &input.spots;
        else in.noise = input.noise.get();
    }
    return in;
}

} // namespace

bool sealingAllowed()
{
    const char* env = std::getenv("LICVDB_SEAL_LEAVES");
    return !(env && std::string(env) == "0");
}

Ranges bakeRanges(const Recipe& recipe, lic::ScalarSet& scalars, const lic::OutputDomain& domain,
                  std::optional<lic::Colormap>& cmap, const std::vector<std::uint32_t>* blocks,
                  const lic::HistogramReduce& reduce)
{
    Ranges r;
    auto autoRange = [&](const std::string& name) {
        return lic::autoRange(lic::ScalarField(scalars.get(name)), domain, recipe.threads, blocks, reduce);
    };
    if (recipe.width) r.width = recipe.width->range ? *recipe.width->range : autoRange(recipe.width->scalar);
    if (recipe.color) {
        cmap = loadColormap(recipe.color->colormap);
        r.color = recipe.color->range ? *recipe.color->range : autoRange(recipe.color->scalar);
    }
    return r;
}

double loopVoxelsPerFrame(const Plan& plan)
{
    const lic::LicSettings& s = plan.settings;
    if (s.comets > 0) return lic::cometSpacing(s, plan.maxSpotRadius) / double(plan.frames);
    return double(lic::detail::ripplePeriod(s)) * s.step / double(plan.frames);
}

SpotShare spotShareOf(const Plan& plan, const FieldShare& share)
{
    SpotShare out;
    out.reach = bricksBox(*share.layout, share.mine, spotReach(plan));
    out.ownBlocks.assign(share.domain->blockCount(), false);
    for (std::size_t id : share.mine)
        for (std::uint32_t b : (*share.layout)[id].blocks) out.ownBlocks[b] = true;
    return out;
}

lic::CompositeSettings compositeSettings(const Plan& plan, const Ranges& ranges)
{
    const Recipe& r = plan.recipe;
    lic::CompositeSettings s;
    s.frames = plan.frames;
    s.comets = plan.settings.comets > 0;
    s.spots = plan.spots;
    s.levels = plan.levels;
    s.linePeak = plan.linePeak;
    s.haloPeak = plan.haloPeak;
    s.stretch = plan.stretch;
    s.widthInvert = r.width && r.width->invert;
    s.widthRange = ranges.width;
    if (plan.roiPost) s.roiRange = r.roi->range;
    s.colorRange = ranges.color;
    s.grids = r.output.grids;
    s.inputRadius = r.input.radii.empty() ? 1.0 : r.input.radii[0];
    s.haloScale = r.input.haloScale;
    s.threads = plan.settings.threads;
    return s;
}

FrameBake::FrameBake(const Plan& plan, Job& job, lic::Progress& progress, FrameOptions options)
    : mPlan(plan)
    , mJob(job)
{
    read(options);
    scalarsAndRanges(options);
    makeTexture(options);
    convolve(progress);
    mergeStatistics();
}

void FrameBake::read(const FrameOptions& options)
{
    // Any format (vdb, npy, vti, vtk, raw), prepared (NaN policy, crop, mask, resample); the file's
    // scalar grids come with it. The output domain and its bricks, and this process's share of
    // them (all of them in one process; in a distributed bake only the part of the field they
    // need, where the format allows: see bake/FieldShare.h).
    const auto t0 = Clock::now();
    partMargin = options.partMarginGuess;
    auto readShare = [&] {
        return mJob.stage("reading the field", [&] {
            return readFieldShare(mPlan, mJob.rank(), mJob.size(), options.wholeField, partMargin);
        });
    };
    share = readShare();
    if (share.partial) {
        const double maxSpeed = mJob.maxAll(share.extent.maxSpeed, "reading the field");
        if (options.partMargin) {
            // The same decision on every rank: it depends on the whole field's largest speed only.
            const int need = mJob.stage("reading the field", [&] { return options.partMargin(share, maxSpeed); });
            if (need > partMargin) {
                partMargin = need;
                share = readShare();
            }
        }
        mJob.stage("reading the field", [&] { makeField(share, maxSpeed); });
    }
    if (mJob.distributed()) {
        mMine.emplace(share.layout->subset(share.mine));
        for (const lic::Brick& b : mMine->bricks()) mMineBlocks.insert(mMineBlocks.end(), b.blocks.begin(), b.blocks.end());
    }
    for (const lic::Brick& b : mine().bricks()) shareVoxels += b.activeVoxels;
    if (options.onField) mJob.stage("reading the field", [&] { options.onField(share); });
    seconds.read = since(t0);
}

void FrameBake::scalarsAndRanges(const FrameOptions& options)
{
    // Scalars by name, and the automatic ranges of width and colour (streamed percentiles;
    // distributed: each rank's histograms of its bricks, summed over the ranks).
    const auto t0 = Clock::now();
    scalars = std::make_unique<lic::ScalarSet>(*share.loaded.velocity, share.loaded.scalars);
    if (options.ranges) {
        ranges = *options.ranges;
        if (mPlan.recipe.color) cmap = loadColormap(mPlan.recipe.color->colormap);
    } else {
        const std::vector<std::uint32_t>* blocks = mJob.distributed() ? &mMineBlocks : nullptr;
        lic::HistogramReduce reduce;
        if (mJob.distributed()) reduce = [&](std::vector<std::uint64_t>& h) { mJob.sumAll(h, "computing scalar ranges"); };
        mJob.stage("computing scalar ranges",
                   [&] { ranges = bakeRanges(mPlan.recipe, *scalars, domain(), cmap, blocks, reduce); });
    }
    seconds.input = since(t0);
}

void FrameBake::makeTexture(const FrameOptions& options)
{
    // Spots placed once (a rank keeps those near its bricks); noise made per brick.
    const auto t0 = Clock::now();
    input = mJob.stage("making the input texture", [&] {
        if (options.input) return options.input(mPlan, share, *scalars);
        if (!mJob.distributed()) return makeInput(mPlan, domain(), *scalars);
        const SpotShare spotShare = spotShareOf(mPlan, share);
        return makeInput(mPlan, domain(), *scalars, &spotShare);
    });
    spotCount = mPlan.spots ? mJob.sumAll(input.spotCount, "making the input texture") : 0;
    mJob.stage("preparing the compositor", [&] {
        lic::CompositeSettings cs = compositeSettings(mPlan, ranges);
        if (cs.writes(lic::OutputGrid::Velocity) && mPlan.frames > 1) {
            // A loop's lines travel along the flow at one speed: output voxels per frame × voxel
            // size × frames per second.
            cs.velocitySpeed = loopVoxelsPerFrame(mPlan) * domain().voxelSize() * mPlan.recipe.field.fps;
        } else if (cs.writes(lic::OutputGrid::Velocity) && options.velocityScale) {
            cs.velocityScale = options.velocityScale(share);
        }
        compositor.emplace(std::move(cs),
                           compositeInputs(mPlan, *scalars, input, cmap ? &*cmap : nullptr), field(), domain(), layout());
        sealed = compositor->sealLeaves(options.sealer);
    });
    seconds.input += since(t0);
}

void FrameBake::convolve(lic::Progress& progress)
{
    // Each brick is composited into leaves as it finishes.
    const lic::BrickSink sink = [&](const lic::BrickChannels& b) { compositor->consume(b); };
    ShareProgress shareProgress(progress, shareVoxels, domain().activeVoxelCount());
    lic::Progress& p = mJob.distributed() ? static_cast<lic::Progress&>(shareProgress) : progress;
    stats = mJob.stage("convolving", [&] {
        const lic::ConvolveJob job{field(), domain(), mine(), mPlan.settings, p};
        const Recipe& r = mPlan.recipe;
        return mPlan.spots ? lic::convolveSpotBricks(job, {input.spots, r.input.radii, r.input.haloScale}, sink)
                           : lic::convolveNoiseBricks(job, *input.noise, sink);
    });
    seconds.convolve = stats.seconds;
}

void FrameBake::mergeStatistics()
{
    const auto t0 = Clock::now();
    if (mJob.distributed()) {
        // Every rank merges every brick's contrast moments, in brick order: the same sums.
        const std::vector<std::string> moments =
            mJob.allGather(compositor->packMoments(share.mine), "merging brick statistics");
        mJob.stage("merging brick statistics", [&] {
            for (int r = 0; r < mJob.size(); ++r)
                if (r != mJob.rank()) compositor->unpackMoments(moments[std::size_t(r)]);
        });
    }
    compositor->finish();
    seconds.compose = since(t0);
}

} // namespace vdbexport::pipeline

#include "vdbexport/bake/Bake.h"

#include "bake/Composite.h"
#include "bake/Distribute.h"
#include "bake/FieldShare.h"
#include "bake/Input.h"
#include "bake/Plan.h"
#include "bake/Scalars.h"
#include "bake/Sequence.h"
#include "bake/Write.h"

#include "vdbexport/io/FieldInput.h"
#include "vdbexport/io/FieldSequence.h"

#include "lic/composite/Colormap.h"
#include "lic/engine/Engine.h"
#include "lic/util/Error.h"

#include <openvdb/openvdb.h>

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

namespace vdbexport {

namespace fs = std::filesystem;

std::string framePath(const std::string& vdbPath, int frame, int frames)
{
    if (frames <= 1) return vdbPath;
    fs::path p(vdbPath);
    char suffix[16];
    std::snprintf(suffix, sizeof suffix, "_%04d", frame);
    const std::string ext = p.extension() == ".vdb" ? ".vdb" : "";
    const fs::path stem = ext.empty() ? p.filename() : p.stem();
    return (p.parent_path() / (stem.string() + suffix + ".vdb")).string();
}

std::string manifestPath(const std::string& vdbPath)
{
    // Not OUT.json: that is what a recipe for OUT.vdb is naturally called (`--recipe jet.json
    // --out jet.vdb`), and the bake would refuse to overwrite it. The add-on still reads OUT.json
    // beside bakes made before the rename (blender_addon/licvdb/manifest.py).
    fs::path p(vdbPath);
    if (p.extension() == ".vdb") p.replace_extension();
    p += manifestSuffix;
    return p.string();
}

void checkNotOverwritten(const Recipe& recipe, const std::string& path, const std::string& what)
{
    if (path.empty()) return;
    std::error_code ec;
    const fs::path input = fs::weakly_canonical(path, ec);
    if (ec) return; // cannot be resolved: reading it will report the problem
    std::vector<std::string> outputs{manifestPath(recipe.output.path)};
    if (isSequenceBake(recipe)) {
        try {
            for (int f : resolveFieldFrames(recipe.field).numbers) outputs.push_back(sequenceFramePath(recipe.output.path, f));
        } catch (const lic::InputError&) {
            // the bake itself reports a sequence it cannot resolve
        }
    } else {
        for (int f = 1; f <= recipe.animation.frames; ++f)
            outputs.push_back(framePath(recipe.output.path, f, recipe.animation.frames));
    }
    for (const auto& out : outputs) {
        std::error_code e1, e2;
        const bool same = fs::equivalent(path, out, e1) || fs::weakly_canonical(out, e2) == input;
        if (same && !e2) {
            throw lic::InputError("the bake would overwrite " + what + " \"" + path + "\" with \"" + out +
                                  "\"; choose another --out");
        }
    }
}

namespace {

/// Peak resident memory of this process so far, MiB (Linux: ru_maxrss is in KiB).
double peakRssMiB()
{
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0;
}

/// CPU time of this process so far (user + system, every thread), seconds: with the wall times,
/// how much of a core a process had (a shared machine gives less than its threads ask for).
double cpuSeconds()
{
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    auto s = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
    return s(u.ru_utime) + s(u.ru_stime);
}

std::string hostName()
{
    char name[256] = {};
    return gethostname(name, sizeof name - 1) == 0 ? std::string(name) : std::string("?");
}

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

} // namespace


// The pipeline of DESIGN.md, top to bottom; each stage lives in src/bake/. In a distributed bake
// (mpirun) every rank runs it on its share of the bricks and rank 0 writes (bake/Distribute.h);
// in one process every Job call below is a no-op.
nlohmann::json bake(const Recipe& request, lic::Progress& progress)
{
    if (isSequenceBake(request)) return pipeline::bakeSequence(request, progress);
    // The engine "auto" is resolved here, so the recipe a bake records names the engine it used.
    Recipe recipe = request;
    if (recipe.lic.engine == "auto") recipe.lic.engine = recipe.input.type == "spots" ? "splat" : "fast";
    using Clock = std::chrono::steady_clock;
    auto seconds = [](Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); };
    const auto t0 = Clock::now();
    pipeline::Job& job = pipeline::Job::current();

    // 1. Plan: every setting and every check that needs only the recipe.
    const pipeline::Plan plan = job.stage("planning the bake", [&] { return pipeline::makePlan(recipe); });
    openvdb::initialize();

    // 2. Field: any format (vdb, npy, vti, vtk, raw), prepared (NaN policy, crop, mask,
    //    resample); the file's scalar grids come with it. The output domain and its bricks, and
    //    this process's share of them (all of them in one process; in a distributed bake only the
    //    part of the field they need, where the format allows: see bake/FieldShare.h).
    pipeline::FieldShare share =
        job.stage("reading the field", [&] { return pipeline::readFieldShare(plan, job.rank(), job.size()); });
    if (share.partial) {
        const double maxSpeed = job.maxAll(share.extent.maxSpeed, "reading the field");
        job.stage("reading the field", [&] { pipeline::makeField(share, maxSpeed); });
    }
    const LoadedField& loaded = share.loaded;
    const lic::VelocityField& field = *share.field;
    const lic::OutputDomain& domain = *share.domain;
    const lic::BrickLayout& layout = *share.layout;
    std::optional<lic::BrickLayout> mineLayout;
    std::vector<std::uint32_t> mineBlocks;
    std::uint64_t mineVoxels = 0;
    if (job.distributed()) {
        mineLayout.emplace(layout.subset(share.mine));
        for (const lic::Brick& b : mineLayout->bricks()) {
            mineBlocks.insert(mineBlocks.end(), b.blocks.begin(), b.blocks.end());
            mineVoxels += b.activeVoxels;
        }
    }
    const lic::BrickLayout& mine = job.distributed() ? *mineLayout : layout;
    const double tRead = seconds(t0);

    // 3. Scalars by name, and the automatic ranges of width and colour (streamed percentiles;
    //    distributed: each rank's histograms of its bricks, summed over the ranks).
    const auto t1 = Clock::now();
    pipeline::ScalarSet scalars(*loaded.velocity, loaded.scalars);
    pipeline::Ranges ranges;
    std::optional<lic::Colormap> cmap;
    const std::vector<std::uint32_t>* blocks = job.distributed() ? &mineBlocks : nullptr;
    pipeline::HistogramReduce reduce;
    if (job.distributed()) reduce = [&](std::vector<std::uint64_t>& h) { job.sumAll(h, "computing scalar ranges"); };
    job.stage("computing scalar ranges", [&] { ranges = pipeline::bakeRanges(recipe, scalars, domain, cmap, blocks, reduce); });

    // 4. Input texture: spots placed once (a rank keeps those near its bricks); noise made per brick.
    pipeline::Input input = job.stage("making the input texture", [&] {
        if (!job.distributed()) return pipeline::makeInput(plan, domain, scalars);
        pipeline::SpotShare spotShare;
        spotShare.reach = bricksBox(layout, share.mine, pipeline::spotReach(plan));
        spotShare.ownBlocks.assign(domain.blockCount(), false);
        for (std::uint32_t b : mineBlocks) spotShare.ownBlocks[b] = true;
        return pipeline::makeInput(plan, domain, scalars, &spotShare);
    });
    const std::uint64_t spotCount = plan.spots ? job.sumAll(input.spotCount, "making the input texture") : 0;
    const double tInput = seconds(t1);

    // 5–6. Convolve each brick and composite it into leaves as it finishes.
    std::optional<pipeline::Compositor> compositor;
    job.stage("preparing the compositor", [&] {
        compositor.emplace(plan, field, domain, layout, scalars, input, cmap ? &*cmap : nullptr, ranges);
    });
    const lic::BrickSink sink = [&](const lic::BrickChannels& b) { compositor->consume(b); };
    ShareProgress shareProgress(progress, mineVoxels, domain.activeVoxelCount());
    lic::Progress& convolveProgress = job.distributed() ? shareProgress : progress;
    const lic::LicStats st = job.stage("convolving", [&] {
        return plan.spots ? lic::convolveSpotBricks(field, domain, mine, input.spots, recipe.input.radii,
                                                    recipe.input.haloScale, plan.settings, convolveProgress, sink)
                          : lic::convolveNoiseBricks(field, domain, mine, *input.noise, plan.settings, convolveProgress, sink);
    });
    const auto t2 = Clock::now();
    if (job.distributed()) {
        // Every rank merges every brick's contrast moments, in brick order: the same sums.
        const std::vector<std::string> moments = job.allGather(compositor->packMoments(share.mine), "merging brick statistics");
        job.stage("merging brick statistics", [&] {
            for (int r = 0; r < job.size(); ++r)
                if (r != job.rank()) compositor->unpackMoments(moments[std::size_t(r)]);
        });
    }
    compositor->finish();
    const double tCompose = seconds(t2);

    // 7. Metadata, files, manifest.
    const auto t3 = Clock::now();
    const nlohmann::json resolved = recipe.toJson();
    pipeline::Description desc =
        pipeline::describeBake(plan, resolved, loaded.gridName, layout.dim(), spotCount, ranges, cmap ? &*cmap : nullptr);
    openvdb::MetaMap& densityMeta = desc.densityMeta; // on `density` of every frame
    densityMeta.insertMeta("lic_frames", openvdb::Int32Metadata(plan.frames));
    densityMeta.insertMeta("lic_cyclic", openvdb::BoolMetadata(plan.frames > 1));
    const nlohmann::json& spotsJson = desc.spots;
    const nlohmann::json& colorJson = desc.color;
    pipeline::Written written;
    double tGather = 0.0;
    if (!job.distributed()) {
        written = pipeline::writeFrames(plan, *compositor, densityMeta, progress);
        pipeline::writeManifest(recipe, resolved, written.paths, *written.output, pipeline::gridsJson(written.firstGrids),
                                    domain.voxelSize(), colorJson, spotsJson);
    } else {
        // Each rank composes its leaves of every frame; rank 0 adds the others' and writes. The
        // static grids (input, tangent, colour) travel with frame 1 only.
        openvdb::GridPtrVec first; // held, so a later frame's grid cannot reuse an address
        auto gather = [&](int f, openvdb::GridPtrVec& grids) {
            std::vector<bool> skip(grids.size(), false);
            if (f == 1) {
                first = grids;
            } else {
                for (std::size_t i = 0; i < grids.size(); ++i)
                    skip[i] = std::find(first.begin(), first.end(), grids[i]) != first.end();
            }
            const auto tg = Clock::now();
            job.gatherLeaves(grids, skip);
            tGather += seconds(tg);
        };
        if (job.root()) {
            std::vector<std::string> framePaths;
            for (int f = 1; f <= plan.frames; ++f) framePaths.push_back(framePath(recipe.output.path, f, plan.frames));
            pipeline::WriteGuard guard(framePaths, manifestPath(recipe.output.path));
            try {
                job.injectFault("writing");
                written = pipeline::writeFrames(plan, *compositor, densityMeta, progress, [&](int f, openvdb::GridPtrVec& grids) {
                    const std::string what = "composing frame " + std::to_string(f);
                    job.injectFault(what.c_str());
                    job.agree(nullptr, what.c_str());
                    gather(f, grids);
                    job.injectFault(("writing frame " + std::to_string(f)).c_str());
                });
                pipeline::writeManifest(recipe, resolved, written.paths, *written.output, pipeline::gridsJson(written.firstGrids),
                                    domain.voxelSize(), colorJson, spotsJson);
                guard.disarm();
            } catch (...) {
                if (job.failed()) throw;
                job.agree(std::current_exception(), "writing");
            }
        } else {
            for (int f = 1; f <= plan.frames; ++f) {
                const std::string what = "composing frame " + std::to_string(f);
                openvdb::GridPtrVec grids = job.stage(what.c_str(), [&] { return compositor->frame(f); });
                gather(f, grids);
            }
        }
        job.agree(nullptr, "writing");
    }
    const double tWrite = seconds(t3);

    // Summary: counters summed over the ranks (each brick's are the same in any share).
    const double total = seconds(t0);
    nlohmann::json rankJson = {
        {"rank", job.rank()}, {"host", hostName()}, {"bricks", mine.size()}, {"active_voxels", job.distributed() ? mineVoxels : st.voxels},
        {"field_voxels_held", share.voxelsHeld}, {"streamlines", st.streamlines}, {"samples", st.samples},
        {"deposits", st.deposits}, {"peak_rss_mib", peakRssMiB()}, {"cpu_seconds", cpuSeconds()},
        {"seconds", {{"read", tRead}, {"input", tInput}, {"convolve", st.seconds}, {"compose", tCompose},
                     {"write", tWrite}, {"gather", tGather}, {"total", total}}}};
    std::uint64_t streamlines = st.streamlines, samples = st.samples, deposits = st.deposits;
    nlohmann::json ranksJson = nlohmann::json::array();
    if (job.distributed()) {
        streamlines = samples = deposits = 0;
        for (const std::string& text : job.allGather(rankJson.dump(), "summarising")) {
            const nlohmann::json j = nlohmann::json::parse(text);
            streamlines += j["streamlines"].get<std::uint64_t>();
            samples += j["samples"].get<std::uint64_t>();
            deposits += j["deposits"].get<std::uint64_t>();
            ranksJson.push_back(j);
        }
    }
    const lic::ChannelStats& raw = compositor->rawStats();
    nlohmann::json summary = {
        {"output", recipe.output.path},
        {"files", written.paths},
        {"frames", plan.frames},
        {"manifest", manifestPath(recipe.output.path)},
        {"field", {{"path", recipe.field.path}, {"grid", loaded.gridName}, {"format", loaded.format}, {"notes", loaded.notes},
                   {"active_voxels", field.activeVoxelCount()}, {"world_bbox", pipeline::bboxJson(field.worldBBox())}}},
        {"engine", recipe.lic.engine},
        {"output_voxels", st.voxels},
        {"output_bbox", {{domain.indexBBox().min()[0], domain.indexBBox().min()[1], domain.indexBBox().min()[2]},
                         {domain.indexBBox().max()[0], domain.indexBBox().max()[1], domain.indexBBox().max()[2]}}},
        {"streamlines", streamlines},
        {"samples", samples},
        {"samples_per_voxel", st.voxels ? double(samples) / double(st.voxels) : 0.0},
        {"deposits", deposits},
        {"bricks", layout.size()},
        {"brick_size", st.brickDim},
        {"spots", spotsJson},
        {"density_active_voxels", written.firstGrids.empty() ? 0 : written.firstGrids.front()->activeVoxelCount()},
        {"raw_mean", raw.mean},
        {"raw_stddev", raw.stddev},
        {"peak_rss_mib", peakRssMiB()},
        {"cpu_seconds", cpuSeconds()},
        {"seconds", {{"read", tRead}, {"input", tInput}, {"convolve", st.seconds}, {"compose", tCompose},
                     {"write", tWrite}, {"total", total}}},
    };
    if (job.distributed()) {
        summary["mpi"] = {{"ranks", job.size()},
                          {"partial_read", share.partial},
                          {"whole_read_reason", share.partial ? nlohmann::json(nullptr) : nlohmann::json(share.wholeReason)},
                          {"assignment", "contiguous runs of bricks in Morton order, balanced by active voxels"}};
        summary["ranks"] = ranksJson;
    }
    return summary;
}

} // namespace vdbexport

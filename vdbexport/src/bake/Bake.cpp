// A still or a cyclic loop: plan, one frame bake (bake/Frame.h), then the frames written with one
// manifest. In a distributed bake (mpirun) every rank bakes its share of the bricks and rank 0
// gathers the leaves and writes (bake/Distribute.h); in one process every Job call is a no-op.
#include "vdbexport/bake/Bake.h"
#include "vdbexport/bake/Outputs.h"

#include "bake/Distribute.h"
#include "bake/Frame.h"
#include "bake/Plan.h"
#include "bake/Sequence.h"
#include "bake/Write.h"

#include "vdbexport/io/FieldSequence.h"
#include "vdbexport/io/SealedLeaves.h"

#include "lic/engine/Engine.h"
#include "lic/util/Parallel.h"

#include <openvdb/openvdb.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <optional>
#include <string>

namespace vdbexport {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

std::string hostName()
{
    char name[256] = {};
    return gethostname(name, sizeof name - 1) == 0 ? std::string(name) : std::string("?");
}

using pipeline::FrameBake;
using pipeline::Job;
using pipeline::Plan;

/// Distributed: each rank composes its leaves of every frame; rank 0 adds the others' and writes.
/// The static grids (input, tangent, colour) travel with frame 1 only. Returns the seconds spent
/// gathering.
double writeDistributed(const Plan& plan, FrameBake& fb, Job& job, const openvdb::MetaMap& densityMeta,
                        const nlohmann::json& resolved, const pipeline::Description& desc, lic::Progress& progress,
                        pipeline::Written& written)
{
    const Recipe& recipe = plan.recipe;
    double tGather = 0.0;
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
        tGather += since(tg);
    };
    if (job.root()) {
        std::vector<std::string> framePaths;
        for (int f = 1; f <= plan.frames; ++f) framePaths.push_back(framePath(recipe.output.path, f, plan.frames));
        pipeline::WriteGuard guard(framePaths, manifestPath(recipe.output.path));
        try {
            job.injectFault("writing");
            written = pipeline::writeFrames(plan, *fb.compositor, densityMeta, progress, [&](int f, openvdb::GridPtrVec& grids) {
                const std::string what = "composing frame " + std::to_string(f);
                job.injectFault(what.c_str());
                job.agree(nullptr, what.c_str());
                gather(f, grids);
                job.injectFault(("writing frame " + std::to_string(f)).c_str());
            });
            pipeline::writeManifest(recipe, resolved, written.paths, *written.output, pipeline::gridsJson(written.firstGrids),
                                    fb.domain().voxelSize(), desc.color, desc.spots);
            guard.disarm();
        } catch (...) {
            if (job.failed()) throw;
            job.agree(std::current_exception(), "writing");
        }
    } else {
        for (int f = 1; f <= plan.frames; ++f) {
            const std::string what = "composing frame " + std::to_string(f);
            openvdb::GridPtrVec grids = job.stage(what.c_str(), [&] { return fb.compositor->frame(f); });
            gather(f, grids);
        }
    }
    job.agree(nullptr, "writing");
    return tGather;
}

/// The summary `licvdb bake --json` prints: counters summed over the ranks (each brick's are the
/// same in any share), per-stage seconds, and in a distributed bake each rank's own.
nlohmann::json summarise(const Recipe& recipe, const Plan& plan, const FrameBake& fb, Job& job,
                         const pipeline::Written& written, const nlohmann::json& spotsJson, double tWrite,
                         double tGather, double total)
{
    const lic::LicStats& st = fb.stats;
    const nlohmann::json seconds = {{"read", fb.seconds.read}, {"input", fb.seconds.input}, {"convolve", st.seconds},
                                    {"compose", fb.seconds.compose}, {"write", tWrite}, {"total", total}};
    nlohmann::json rankJson = {
        {"rank", job.rank()}, {"host", hostName()}, {"bricks", fb.mine().size()},
        {"active_voxels", job.distributed() ? fb.shareVoxels : st.voxels}, {"field_voxels_held", fb.share.voxelsHeld},
        {"streamlines", st.streamlines}, {"samples", st.samples}, {"deposits", st.deposits},
        {"peak_rss_mib", pipeline::peakRssMiB()}, {"cpu_seconds", pipeline::cpuSeconds()}, {"seconds", seconds}};
    rankJson["seconds"]["gather"] = tGather;
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
    const lic::OutputDomain& domain = fb.domain();
    const LoadedField& loaded = fb.share.loaded;
    const openvdb::CoordBBox& ob = domain.indexBBox();
    nlohmann::json summary = {
        {"output", recipe.output.path},
        {"files", written.paths},
        {"frames", plan.frames},
        {"manifest", manifestPath(recipe.output.path)},
        {"field", {{"path", recipe.field.path}, {"grid", loaded.gridName}, {"format", loaded.format}, {"notes", loaded.notes},
                   {"active_voxels", fb.field().activeVoxelCount()}, {"world_bbox", pipeline::bboxJson(fb.field().worldBBox())}}},
        {"engine", recipe.lic.engine},
        {"output_voxels", st.voxels},
        {"output_bbox", {{ob.min()[0], ob.min()[1], ob.min()[2]}, {ob.max()[0], ob.max()[1], ob.max()[2]}}},
        {"streamlines", streamlines},
        {"samples", samples},
        {"samples_per_voxel", st.voxels ? double(samples) / double(st.voxels) : 0.0},
        {"deposits", deposits},
        {"sealed_leaves", fb.sealed},
        {"bricks", fb.layout().size()},
        {"brick_size", st.brickDim},
        {"spots", spotsJson},
        {"density_active_voxels", written.firstGrids.empty() ? 0 : written.firstGrids.front()->activeVoxelCount()},
        {"raw_mean", fb.compositor->rawStats().mean},
        {"raw_stddev", fb.compositor->rawStats().stddev},
        {"peak_rss_mib", pipeline::peakRssMiB()},
        {"cpu_seconds", pipeline::cpuSeconds()},
        {"seconds", seconds},
    };
    if (job.distributed()) {
        summary["mpi"] = {{"ranks", job.size()},
                          {"partial_read", fb.share.partial},
                          {"whole_read_reason", fb.share.partial ? nlohmann::json(nullptr) : nlohmann::json(fb.share.wholeReason)},
                          {"assignment", "contiguous runs of bricks in Morton order, balanced by active voxels"}};
        summary["ranks"] = ranksJson;
    }
    return summary;
}

} // namespace

nlohmann::json bake(const Recipe& request, lic::Progress& progress)
{
    const lic::ThreadLimit threads(request.threads); // every stage of the bake
    if (isSequenceBake(request)) return pipeline::bakeSequence(request, progress);
    // The engine "auto" is resolved here, so the recipe a bake records names the engine it used.
    Recipe recipe = request;
    if (recipe.lic.engine == "auto") recipe.lic.engine = lic::toString(lic::chooseEngine("auto", recipe.input.type == "spots"));
    const auto t0 = Clock::now();
    Job& job = Job::current();
    const Plan plan = job.stage("planning the bake", [&] { return pipeline::makePlan(recipe); });
    openvdb::initialize();
    // One process: a spot still's leaves are sealed (compressed for the file) as its bricks
    // finish, so the bake holds its compressed output instead of float leaves
    // (vdbexport/io/SealedLeaves.h); a loop's records, every frame's, are spooled to an unnamed
    // file in the output directory. LICVDB_SEAL_LEAVES=0 keeps whole leaves (the same files).
    std::optional<detail::SealedLeaves> sealer;
    if (!job.distributed() && pipeline::sealingAllowed()) {
        sealer.emplace(recipe.output.half,
                       plan.frames > 1 ? pipeline::outputDirectory(recipe.output.path) : std::string());
    }
    pipeline::FrameOptions frameOptions;
    frameOptions.sealer = sealer ? &*sealer : nullptr;
    FrameBake fb(plan, job, progress, std::move(frameOptions));
    if (fb.sealed) sealer->flush(); // every leaf is sealed: a loop's last spooled records to disk
    const detail::SealedLeaves* sealed = fb.sealed ? &*sealer : nullptr;

    // Metadata, files, manifest.
    const auto t3 = Clock::now();
    const nlohmann::json resolved = recipe.toJson();
    pipeline::Description desc = pipeline::describeBake(plan, resolved, fb.share.loaded.gridName, fb.layout().dim(),
                                                        fb.spotCount, fb.ranges, fb.cmap ? &*fb.cmap : nullptr);
    pipeline::describeSeeds(desc, recipe, fb.input);
    openvdb::MetaMap& densityMeta = desc.densityMeta; // on `density` of every frame
    densityMeta.insertMeta("lic_frames", openvdb::Int32Metadata(plan.frames));
    densityMeta.insertMeta("lic_cyclic", openvdb::BoolMetadata(plan.frames > 1));
    pipeline::Written written;
    double tGather = 0.0;
    if (!job.distributed()) {
        written = pipeline::writeFrames(plan, *fb.compositor, densityMeta, progress, {}, sealed);
        pipeline::writeManifest(recipe, resolved, written.paths, *written.output, pipeline::gridsJson(written.firstGrids),
                                fb.domain().voxelSize(), desc.color, desc.spots);
    } else {
        tGather = writeDistributed(plan, fb, job, densityMeta, resolved, desc, progress, written);
    }
    nlohmann::json summary = summarise(recipe, plan, fb, job, written, desc.spots, since(t3), tGather, since(t0));
    // The grids whose leaves were sealed (compressed as their bricks finished), by name.
    summary["sealed_grids"] = sealed ? sealed->names() : std::vector<std::string>{};
    return summary;
}

} // namespace vdbexport

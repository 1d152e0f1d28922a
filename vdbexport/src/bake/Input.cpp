#include "Input.h"

#include "vdbexport/io/SeedPoints.h"

#include "lic/engine/Engine.h"
#include "lic/field/Bricks.h"
#include "lic/util/Error.h"
#include "lic/field/Region.h"

#include <memory>
#include <optional>

namespace vdbexport::pipeline {

namespace {

/// Spots evenly on the ridge surface of `surface` (output index space).
std::vector<openvdb::Vec3d> surfaceSpots(const Recipe& r, const lic::OutputDomain& domain, const openvdb::FloatGrid& surface)
{
    std::vector<openvdb::Vec3d> candidates = lic::ridgePoints(surface, r.input.surface->threshold);
    for (auto& c : candidates) c = domain.map().toIndex(c);
    if (candidates.empty()) {
        throw lic::InputError("input.surface: the scalar '" + r.input.surface->scalar +
                              "' has no ridge above threshold " + std::to_string(r.input.surface->threshold) +
                              "; lower the threshold (see `licvdb info` for the field's grids)");
    }
    return lic::selectEvenly(candidates, lic::kPoissonRadius * r.input.spacing, r.input.seed);
}

/// The points of the seeds file (world units) in output index space, in file order; `in` gets
/// how many the file holds and how many lie off the output domain's active voxels (dropped).
std::vector<openvdb::Vec3d> seedSpots(const Recipe& r, const lic::OutputDomain& domain, Input& in)
{
    std::vector<openvdb::Vec3d> points;
    try {
        points = readSeedPoints(r.input.seeds);
    } catch (const lic::InputError& e) {
        throw lic::InputError(std::string("input.seeds: ") + e.what());
    }
    in.seedsRead = points.size();
    std::vector<openvdb::Vec3d> centers;
    centers.reserve(points.size());
    for (const auto& w : points) {
        const openvdb::Vec3d c = domain.map().toIndex(w);
        if (domain.slotOf(lic::OutputDomain::nearestVoxel(c)) < 0) continue;
        centers.push_back(c);
    }
    in.seedsDropped = points.size() - centers.size();
    return centers;
}

/// Spots of the distribution over the output box (output index space).
std::vector<openvdb::Vec3d> distributedSpots(const Recipe& r, const lic::OutputDomain& domain)
{
    const openvdb::CoordBBox ib = domain.indexBBox();
    const openvdb::BBoxd box(ib.min().asVec3d() - openvdb::Vec3d(0.5), ib.max().asVec3d() + openvdb::Vec3d(0.5));
    return lic::placeSpots({lic::spotDistributionFromString(r.input.distribution), r.input.spacing, r.input.jitter,
                            r.input.seed},
                           box);
}

/// The spot centres of a bake (output index space) and their intensities: from the seeds file,
/// evenly on the ridge surface of `surface`, or placed by the distribution over the output box;
/// only spots on active output voxels are kept; with a pre-mode ROI each spot is weighted by the
/// mask at its centre and spots outside the region are dropped. `in.spotCount` counts the spots
/// whose centre lies in this process's blocks.
lic::SpotSet makeSpotSet(const Recipe& r, const lic::OutputDomain& domain, openvdb::FloatGrid::ConstPtr roiPre,
                         const openvdb::FloatGrid* surface, const SpotShare* share, Input& in)
{
    const std::vector<openvdb::Vec3d> centers = !r.input.seeds.empty() ? seedSpots(r, domain, in)
                                                : surface              ? surfaceSpots(r, domain, *surface)
                                                                       : distributedSpots(r, domain);
    std::optional<lic::ScalarField> probe;
    if (roiPre) probe.emplace(roiPre);
    lic::SpotSet set;
    in.spotCount = 0;
    for (const auto& c : centers) {
        if (share && !share->reach.isInside(c)) continue;
        const openvdb::Coord nearest = lic::OutputDomain::nearestVoxel(c);
        if (domain.slotOf(nearest) < 0) continue;
        float w = 1.0f;
        if (probe) w = lic::roiWeight(probe->at(domain.map().toWorld(c)), r.roi->range[0], r.roi->range[1]);
        if (w <= 0.0f) continue;
        set.centers.push_back(c);
        set.weights.push_back(w);
        if (!share || share->ownBlocks[std::size_t(domain.blockOf(nearest))]) ++in.spotCount;
    }
    return set;
}

} // namespace

lic::SpotSet spotsOfShare(const lic::SpotSet& all, const lic::OutputDomain& domain, const SpotShare& share,
                          std::uint64_t& owned)
{
    lic::SpotSet set;
    owned = 0;
    for (std::size_t i = 0; i < all.centers.size(); ++i) {
        const openvdb::Vec3d& c = all.centers[i];
        if (!share.reach.isInside(c)) continue;
        set.centers.push_back(c);
        set.weights.push_back(i < all.weights.size() ? all.weights[i] : 1.0f);
        const std::int64_t b = domain.blockOf(lic::OutputDomain::nearestVoxel(c));
        if (b >= 0 && share.ownBlocks[std::size_t(b)]) ++owned;
    }
    return set;
}

Input makeInput(const Plan& plan, const lic::OutputDomain& domain, lic::ScalarSet& scalars, const SpotShare* share,
                lic::NoiseTexture::RawNoise raw)
{
    const Recipe& r = plan.recipe;
    Input in;
    if (plan.spots) {
        openvdb::FloatGrid::ConstPtr roi = plan.roiPre ? scalars.get(r.roi->scalar) : nullptr;
        openvdb::FloatGrid::ConstPtr surface = r.input.surface ? scalars.get(r.input.surface->scalar) : nullptr;
        in.spots = makeSpotSet(r, domain, roi, surface.get(), share, in);
        return in;
    }
    lic::NoiseBrickSource::Premask premask;
    if (plan.roiPre) {
        // Pre-mask: the noise itself is weighted, so the region's edge runs along the flow.
        auto roi = std::make_shared<const lic::ScalarField>(scalars.get(r.roi->scalar));
        const std::array<double, 2> range = r.roi->range;
        premask = [roi, range, &domain](lic::NoiseTexture& t) {
            t.multiply([&](const openvdb::Coord& ijk) { return lic::roiWeight(roi->at(domain.worldOf(ijk)), range[0], range[1]); },
                       false);
        };
    }
    in.noise = std::make_unique<lic::NoiseBrickSource>(r.input.seed, lic::noiseFilterFromString(r.input.noiseFilter),
                                                       lic::ghostMargin(plan.settings), std::move(premask), std::move(raw));
    return in;
}

} // namespace vdbexport::pipeline

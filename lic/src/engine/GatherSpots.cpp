// The gather engines over the K-level spot texture (K = 1 … 4), compiled once here for every K
// (the engine table points at them).
#include "lic/engine/Gather.h"
#include "lic/texture/Spots.h"

#include <array>

namespace lic {

namespace {
/// Call fn(texture) with the K-level spot texture, K = radii.size() in [1, 4].
template<typename Fn>
auto withSpotTexture(const SpotInput& in, Fn&& fn)
{
    auto run = [&]<int K>() {
        std::array<double, K> r{};
        std::copy(in.radii.begin(), in.radii.end(), r.begin());
        const SpotTexture<K> texture(in.spots, r, in.haloScale);
        return fn(texture);
    };
    switch (in.radii.size()) {
    case 1: return run.template operator()<1>();
    case 2: return run.template operator()<2>();
    case 3: return run.template operator()<3>();
    case 4: return run.template operator()<4>();
    default:
        throw InputError("input.radii has " + std::to_string(in.radii.size()) +
                         " radii; between 1 and 4 width levels are supported");
    }
}
} // namespace

template<typename Engine>
LicStats gatherSpotBricks(const ConvolveJob& job, const SpotInput& spots, const BrickSink& sink)
{
    return withSpotTexture(spots, [&](const auto& texture) {
        using Texture = std::remove_cvref_t<decltype(texture)>;
        return gatherBricks<Engine>(
            job.field, job.domain, job.layout, [&](const Brick&) -> const Texture& { return texture; }, job.settings,
            job.progress, sink);
    });
}

template LicStats gatherSpotBricks<NaiveEngine>(const ConvolveJob&, const SpotInput&, const BrickSink&);
template LicStats gatherSpotBricks<FastEngine>(const ConvolveJob&, const SpotInput&, const BrickSink&);

} // namespace lic

// Cost of halos and width series: one trace convolves every channel, so line + halo and
// 3 widths + 3 halos should cost little more than one line. Poisson spots on the tabbed-jet
// field (60×60×88 at upsample 2 = 2.5 M output voxels), length 20, step 0.5.
// Run: build/tests/bench_spots   (about a minute on 2 cores)
#include "lic/engine/Engine.h"
#include "lic/engine/Gather.h"
#include "lic/field/Presets.h"
#include "lic/texture/Noise.h"
#include "lic/texture/Spots.h"

#include <benchmark/benchmark.h>

namespace {

struct Setup
{
    lic::VelocityField field;
    lic::OutputDomain domain;
    lic::SpotSet spots;
    Setup()
        : field(lic::makePresetField("tabbed-jet", openvdb::Coord(60, 60, 88)).velocity)
        , domain(field, 2)
    {
        const openvdb::CoordBBox ib = domain.indexBBox();
        spots.centers = lic::placeSpots({lic::SpotDistribution::Poisson, 6.0, 0.25, 7},
                                        openvdb::BBoxd(ib.min().asVec3d(), ib.max().asVec3d()));
        spots.weights.assign(spots.centers.size(), 1.0f);
    }
};

Setup& setup()
{
    static Setup s;
    return s;
}

template<typename Texture>
void run(benchmark::State& state, const Texture& texture)
{
    Setup& s = setup();
    lic::LicSettings settings;
    settings.length = 20;
    settings.step = 0.5;
    lic::LicStats stats;
    for (auto _ : state) {
        lic::LicResult r = lic::convolve(s.field, s.domain, texture, settings);
        stats = r.stats;
        benchmark::DoNotOptimize(r.channels[0].data());
    }
    state.counters["voxels"] = double(stats.voxels);
    state.counters["channels"] = Texture::kChannels;
    state.counters["samples/voxel"] = stats.samplesPerVoxel();
    state.counters["spots"] = double(s.spots.centers.size());
}

void noise(benchmark::State& state)
{
    const lic::NoiseTexture tex(1, setup().domain.indexBBox());
    run(state, tex);
}
void line(benchmark::State& state)
{
    run(state, lic::SpotTexture<1, false>(setup().spots, {1.5}, 2.0));
}
void lineHalo(benchmark::State& state)
{
    run(state, lic::SpotTexture<1, true>(setup().spots, {1.5}, 2.0));
}
void widths3(benchmark::State& state)
{
    run(state, lic::SpotTexture<3, false>(setup().spots, {1.0, 1.5, 2.0}, 2.0));
}
void widths3Halos(benchmark::State& state)
{
    run(state, lic::SpotTexture<3, true>(setup().spots, {1.0, 1.5, 2.0}, 2.0));
}

} // namespace

BENCHMARK(noise)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();
BENCHMARK(line)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();
BENCHMARK(lineHalo)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();
BENCHMARK(widths3)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();
BENCHMARK(widths3Halos)->Unit(benchmark::kSecond)->Iterations(2)->UseRealTime();

BENCHMARK_MAIN();

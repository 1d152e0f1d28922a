// Fast-LIC vs naive LIC on a noise bake of a 64³ ABC field at upsample 2 (128³ output voxels).
// Run: build/tests/bench_lic   (takes a few minutes: the naive engine is the slow reference)
#include "lic/Engine.h"
#include "lic/FieldPresets.h"
#include "lic/Noise.h"

#include <benchmark/benchmark.h>

namespace {

struct Setup
{
    lic::VelocityField field;
    lic::OutputDomain domain;
    lic::NoiseTexture noise;
    Setup()
        : field(lic::makePresetField("abc", openvdb::Coord(64)).velocity)
        , domain(field, 2)
        , noise(1, domain.indexBBox())
    {
    }
};

Setup& setup()
{
    static Setup s;
    return s;
}

void bake(benchmark::State& state, lic::EngineType engine, double length, int minHits = 2)
{
    Setup& s = setup();
    lic::LicSettings settings;
    settings.engine = engine;
    settings.length = length;
    settings.step = 0.5;
    settings.minHits = minHits;
    lic::LicStats stats;
    for (auto _ : state) {
        lic::LicResult r = lic::convolve(s.field, s.domain, s.noise, settings);
        stats = r.stats;
        benchmark::DoNotOptimize(r.channels[0].data());
    }
    state.counters["voxels"] = double(stats.voxels);
    state.counters["samples/voxel"] = stats.samplesPerVoxel();
    state.counters["streamlines"] = double(stats.streamlines);
    state.counters["Mvoxels/s"] =
        benchmark::Counter(double(stats.voxels) * double(state.iterations()) / 1e6, benchmark::Counter::kIsRate);
}

} // namespace

BENCHMARK_CAPTURE(bake, naive_L20, lic::EngineType::Naive, 20.0)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L10, lic::EngineType::Fast, 10.0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20, lic::EngineType::Fast, 20.0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20_minhits1, lic::EngineType::Fast, 20.0, 1)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L40, lic::EngineType::Fast, 40.0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();

BENCHMARK_MAIN();

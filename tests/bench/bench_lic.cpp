// Fast-LIC vs naive LIC on a noise bake of a 64³ ABC field at upsample 2 (128³ output voxels),
// as `licvdb bake` runs it (bricks, the noise made per brick), 2 threads.
//
// `reference_naive` is a plain naive gather loop written here, independent of the engines: for
// every output voxel, ±40 RK4 steps of 0.5 voxel through a dense copy of the field with its own
// trilinear interpolation, averaging the same binomial noise. It is the yardstick of issue 13's
// targets (fast ≥ 15× faster, goal 30×).
//
// Run: build/tests/bench_lic [--benchmark_filter=fast]   (the naive rows take ~10–25 s each)
#include "lic/engine/Engine.h"
#include "lic/engine/Gather.h"
#include "lic/field/Presets.h"
#include "lic/texture/Noise.h"

#include <benchmark/benchmark.h>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <sys/resource.h>

#include <cmath>
#include <mutex>
#include <vector>

namespace {

constexpr int kThreads = 2;

struct Setup
{
    lic::PresetField preset;
    lic::VelocityField field;
    lic::OutputDomain domain;
    lic::NoiseTexture noise;
    Setup()
        : preset(lic::makePresetField("abc", openvdb::Coord(64)))
        , field(preset.velocity)
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

/// CPU seconds of the whole process (all threads): on a shared machine, where wall time
/// depends on the other jobs, the fairer figure to compare.
double processCpuSeconds()
{
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

/// Times each iteration's process CPU into the "cpu_s" counter.
struct CpuTimer
{
    benchmark::State& state;
    double start = processCpuSeconds();
    ~CpuTimer() { state.counters["cpu_s"] = (processCpuSeconds() - start) / double(state.iterations()); }
};

void report(benchmark::State& state, const lic::LicStats& stats)
{
    state.counters["voxels"] = double(stats.voxels);
    state.counters["samples/voxel"] = stats.samplesPerVoxel();
    state.counters["streamlines"] = double(stats.streamlines);
    state.counters["bricks"] = double(stats.bricks);
    state.counters["Mvoxels/s"] =
        benchmark::Counter(double(stats.voxels) * double(state.iterations()) / 1e6, benchmark::Counter::kIsRate);
}

/// The engine as a bake runs it: per-brick noise with the ghost margin.
void bake(benchmark::State& state, lic::EngineType engine, double length, int brick = 0, int stride = 0,
          int minHits = 2)
{
    Setup& s = setup();
    lic::LicSettings settings;
    settings.engine = engine;
    settings.length = length;
    settings.step = 0.5;
    settings.minHits = minHits;
    settings.threads = kThreads;
    settings.brick = brick;
    settings.stride = stride;
    const lic::BrickLayout layout(s.domain, lic::brickDim(settings));
    lic::LicStats stats;
    CpuTimer cpu{state};
    for (auto _ : state) {
        lic::NoiseBrickSource noise(1, lic::NoiseFilter::Binomial, lic::ghostMargin(settings));
        double checksum = 0;
        std::mutex m;
        stats = lic::convolveBricks(s.field, s.domain, layout, noise, settings, lic::nullProgress(),
                                    [&](const lic::BrickChannels& b) {
                                        const std::lock_guard lock(m);
                                        checksum += double(b.values[0]);
                                    });
        benchmark::DoNotOptimize(checksum);
    }
    report(state, stats);
}

/// Independent plain naive LIC (see the file comment).
void referenceNaive(benchmark::State& state)
{
    Setup& s = setup();
    const openvdb::Vec3SGrid& g = *s.preset.velocity;
    const openvdb::CoordBBox fb = g.evalActiveVoxelBoundingBox();
    const openvdb::Coord dim = fb.dim();
    std::vector<openvdb::Vec3f> dense(std::size_t{0} + std::size_t(dim[0]) * std::size_t(dim[1]) * std::size_t(dim[2]));
    {
        auto acc = g.getConstAccessor();
        for (int i = 0; i < dim[0]; ++i)
            for (int j = 0; j < dim[1]; ++j)
                for (int k = 0; k < dim[2]; ++k)
                    dense[(std::size_t(i) * dim[1] + j) * dim[2] + k] = acc.getValue(fb.min() + openvdb::Coord(i, j, k));
    }
    const double K = 2.0;                         // upsample
    const double h = 0.5 / K;                     // 0.5 output voxel, in field voxels
    const openvdb::Vec3d lo = fb.min().asVec3d() - openvdb::Vec3d(0.5), hi = fb.max().asVec3d() + openvdb::Vec3d(0.5);
    // Unit direction at a field-index position; false outside or at zero speed. Trilinear, each
    // axis' two lattice indices clamped to the box (the outer half voxel repeats the edge).
    auto dir = [&](const openvdb::Vec3d& p, openvdb::Vec3d& d) {
        for (int a = 0; a < 3; ++a)
            if (p[a] < lo[a] || p[a] > hi[a]) return false;
        const openvdb::Vec3d q = p - fb.min().asVec3d();
        const double x = std::floor(q[0]), y = std::floor(q[1]), z = std::floor(q[2]);
        const double fx = q[0] - x, fy = q[1] - y, fz = q[2] - z;
        const std::size_t i0 = std::clamp(int(x), 0, dim[0] - 1), i1 = std::clamp(int(x) + 1, 0, dim[0] - 1);
        const std::size_t j0 = std::clamp(int(y), 0, dim[1] - 1), j1 = std::clamp(int(y) + 1, 0, dim[1] - 1);
        const std::size_t k0 = std::clamp(int(z), 0, dim[2] - 1), k1 = std::clamp(int(z) + 1, 0, dim[2] - 1);
        auto at = [&](std::size_t i, std::size_t j, std::size_t k) {
            return openvdb::Vec3d(dense[(i * dim[1] + j) * dim[2] + k]);
        };
        const openvdb::Vec3d c00 = at(i0, j0, k0) * (1 - fz) + at(i0, j0, k1) * fz;
        const openvdb::Vec3d c01 = at(i0, j1, k0) * (1 - fz) + at(i0, j1, k1) * fz;
        const openvdb::Vec3d c10 = at(i1, j0, k0) * (1 - fz) + at(i1, j0, k1) * fz;
        const openvdb::Vec3d c11 = at(i1, j1, k0) * (1 - fz) + at(i1, j1, k1) * fz;
        const openvdb::Vec3d v = (c00 * (1 - fy) + c01 * fy) * (1 - fx) + (c10 * (1 - fy) + c11 * fy) * fx;
        const double len = v.length();
        if (!(len > 1e-9)) return false;
        d = v / len;
        return true;
    };
    const openvdb::CoordBBox ob = s.domain.indexBBox();
    const std::size_t n = std::size_t(ob.dim()[0]) * ob.dim()[1] * ob.dim()[2];
    std::vector<float> out(n);
    tbb::task_arena arena(kThreads);
    CpuTimer cpu{state};
    for (auto _ : state) {
        arena.execute([&] {
            tbb::parallel_for(std::size_t(0), n, [&](std::size_t v) {
                const int i = int(v / (std::size_t(ob.dim()[1]) * ob.dim()[2]));
                const int j = int((v / ob.dim()[2]) % ob.dim()[1]), k = int(v % ob.dim()[2]);
                const openvdb::Coord o = ob.min() + openvdb::Coord(i, j, k);
                const openvdb::Vec3d seed((o[0] + 0.5) / K - 0.5, (o[1] + 0.5) / K - 0.5, (o[2] + 0.5) / K - 0.5);
                float t;
                s.noise.sample(o.asVec3d(), &t);
                double sum = t;
                int count = 1;
                for (double sign : {1.0, -1.0}) {
                    openvdb::Vec3d x = seed, k1, k2, k3, k4;
                    for (int step = 0; step < 40; ++step) {
                        if (!dir(x, k1) || !dir(x + k1 * (0.5 * h * sign), k2) || !dir(x + k2 * (0.5 * h * sign), k3) ||
                            !dir(x + k3 * (h * sign), k4))
                            break;
                        x += (k1 + 2.0 * (k2 + k3) + k4) * (h * sign / 6.0);
                        s.noise.sample((x + openvdb::Vec3d(0.5)) * K - openvdb::Vec3d(0.5), &t);
                        sum += t;
                        ++count;
                    }
                }
                out[v] = float(sum / count);
            });
        });
        benchmark::DoNotOptimize(out.data());
    }
    lic::LicStats stats;
    stats.voxels = n;
    report(state, stats);
}

using lic::EngineType;

} // namespace

BENCHMARK(referenceNaive)->Name("reference_naive_L20")->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(bake, naive_L20, EngineType::Naive, 20.0)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L10, EngineType::Fast, 10.0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20, EngineType::Fast, 20.0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L40, EngineType::Fast, 40.0)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20_minhits1, EngineType::Fast, 20.0, 0, 0, 1)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
// Tuning rows: brick edge and integration stride (samples per RK4 step).
BENCHMARK_CAPTURE(bake, fast_L20_brick32, EngineType::Fast, 20.0, 32)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20_brick128, EngineType::Fast, 20.0, 128)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20_stride1, EngineType::Fast, 20.0, 0, 1)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L20_stride2, EngineType::Fast, 20.0, 0, 2)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L40_brick64, EngineType::Fast, 40.0, 64)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();
BENCHMARK_CAPTURE(bake, fast_L40_brick128, EngineType::Fast, 40.0, 128)->Unit(benchmark::kSecond)->Iterations(3)->UseRealTime();

BENCHMARK_MAIN();

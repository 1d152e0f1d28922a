// Fast-LIC vs naive LIC on a noise bake of a 64³ ABC field at upsample 2 (128³ output voxels),
// as `licvdb bake` runs it (bricks, the noise made per brick), 2 threads.
//
// `reference_naive` is the yardstick (issue 29): a naive LIC as a competent engineer writes it in
// an afternoon, independent of the engines — float; the field resampled once into dense arrays at
// the output resolution; hand-written trilinear interpolation; unit-speed RK4; ±40 steps of ½
// output voxel; the same binomial noise looked up at the nearest output voxel; two plain threads.
// It reports ns_per_step_core (CPU time per RK4 step). Until 2026-12 this row was a slower loop
// (double precision through openvdb::Vec3d, clamped lookups, Noise::sample), 1.5× slower than this
// one on a quiet machine (docs/performance.md, "The yardstick").
//
// Run: build/tests/bench_lic [--benchmark_filter=fast]   (the naive rows take ~10–25 s each)
#include "lic/engine/Engine.h"
#include "lic/engine/Gather.h"
#include "lic/field/Presets.h"
#include "lic/texture/Noise.h"

#include "Allocator.h"

#include <benchmark/benchmark.h>

#include <openvdb/tools/Interpolation.h>

#include <sys/resource.h>

#include <cmath>
#include <mutex>
#include <thread>
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
    /// Process CPU seconds per iteration so far.
    double perIteration() const { return (processCpuSeconds() - start) / double(state.iterations()); }
    ~CpuTimer() { state.counters["cpu_s"] = perIteration(); }
};

void report(benchmark::State& state, const lic::LicStats& stats)
{
    state.counters["voxels"] = double(stats.voxels);
    state.counters["samples/voxel"] = stats.samplesPerVoxel();
    state.counters["streamlines"] = double(stats.streamlines);
    state.counters["bricks"] = double(stats.bricks);
    if (stats.speculated > 0) {
        state.counters["speculated"] = double(stats.speculated);
        state.counters["dropped"] = double(stats.dropped);
    }
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
        stats = lic::convolveNoiseBricks({s.field, s.domain, layout, settings, lic::nullProgress()}, noise,
                                         [&](const lic::BrickChannels& b) {
                                             const std::lock_guard lock(m);
                                             checksum += double(b.values[0]);
                                         });
        benchmark::DoNotOptimize(checksum);
    }
    report(state, stats);
}

/// The tight naive LIC (see the file comment): float, the field and the noise as dense arrays at
/// the output resolution, hand-written trilinear interpolation, unit-speed RK4, nearest-voxel
/// noise, ±40 steps of ½ voxel, two plain threads each taking every other x slab.
struct TightInputs
{
    int n[3] = {0, 0, 0};                    // output voxels per axis
    std::vector<float> vx, vy, vz, noise;    // [(i * n1 + j) * n2 + k]
    std::size_t at(int i, int j, int k) const { return (std::size_t(i) * n[1] + j) * n[2] + k; }
};

/// The ABC field resampled trilinearly at the output voxels' centres (OpenVDB's own sampler), and
/// the noise texture's values at the output voxels: inputs, not timed.
const TightInputs& tightInputs()
{
    static const TightInputs in = [] {
        Setup& s = setup();
        TightInputs t;
        const openvdb::CoordBBox ob = s.domain.indexBBox();
        for (int a = 0; a < 3; ++a) t.n[a] = ob.dim()[a];
        const std::size_t count = std::size_t(t.n[0]) * t.n[1] * t.n[2];
        t.vx.resize(count), t.vy.resize(count), t.vz.resize(count), t.noise.resize(count);
        const double K = s.domain.upsample();
        openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> sampler(*s.preset.velocity);
        for (int i = 0; i < t.n[0]; ++i)
            for (int j = 0; j < t.n[1]; ++j)
                for (int k = 0; k < t.n[2]; ++k) {
                    const openvdb::Coord o = ob.min() + openvdb::Coord(i, j, k);
                    const openvdb::Vec3d fieldIndex((o[0] + 0.5) / K - 0.5, (o[1] + 0.5) / K - 0.5, (o[2] + 0.5) / K - 0.5);
                    const openvdb::Vec3s v = sampler.isSample(fieldIndex);
                    const std::size_t c = t.at(i, j, k);
                    t.vx[c] = v[0], t.vy[c] = v[1], t.vz[c] = v[2];
                    t.noise[c] = s.noise.voxel(o);
                }
        return t;
    }();
    return in;
}

/// Trilinear velocity at output-index position p (voxel centres at integers), normalised; false
/// outside [0, n-1] or at zero speed.
inline bool tightDir(const TightInputs& t, float px, float py, float pz, float d[3])
{
    if (!(px >= 0.f && py >= 0.f && pz >= 0.f && px <= float(t.n[0] - 1) && py <= float(t.n[1] - 1) && pz <= float(t.n[2] - 1)))
        return false;
    const int i = std::min(int(px), t.n[0] - 2), j = std::min(int(py), t.n[1] - 2), k = std::min(int(pz), t.n[2] - 2);
    const float fx = px - float(i), fy = py - float(j), fz = pz - float(k);
    const std::size_t c000 = t.at(i, j, k), dk = 1, dj = std::size_t(t.n[2]), di = std::size_t(t.n[1]) * t.n[2];
    float v[3];
    const float* comp[3] = {t.vx.data(), t.vy.data(), t.vz.data()};
    for (int a = 0; a < 3; ++a) {
        const float* f = comp[a] + c000;
        const float c00 = f[0] + fz * (f[dk] - f[0]), c01 = f[dj] + fz * (f[dj + dk] - f[dj]);
        const float c10 = f[di] + fz * (f[di + dk] - f[di]), c11 = f[di + dj] + fz * (f[di + dj + dk] - f[di + dj]);
        const float c0 = c00 + fy * (c01 - c00), c1 = c10 + fy * (c11 - c10);
        v[a] = c0 + fx * (c1 - c0);
    }
    const float len2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if (!(len2 > 1e-18f)) return false;
    const float inv = 1.f / std::sqrt(len2);
    d[0] = v[0] * inv, d[1] = v[1] * inv, d[2] = v[2] * inv;
    return true;
}

/// One output voxel's LIC value; adds the RK4 steps taken to `steps`.
inline float tightVoxel(const TightInputs& t, int i, int j, int k, std::uint64_t& steps)
{
    constexpr float h = 0.5f; // output voxels
    float sum = t.noise[t.at(i, j, k)];
    int count = 1;
    for (const float sign : {1.f, -1.f}) {
        const float hs = h * sign;
        float x = float(i), y = float(j), z = float(k), k1[3], k2[3], k3[3], k4[3];
        for (int step = 0; step < 40; ++step) {
            if (!tightDir(t, x, y, z, k1) || !tightDir(t, x + 0.5f * hs * k1[0], y + 0.5f * hs * k1[1], z + 0.5f * hs * k1[2], k2)
                || !tightDir(t, x + 0.5f * hs * k2[0], y + 0.5f * hs * k2[1], z + 0.5f * hs * k2[2], k3)
                || !tightDir(t, x + hs * k3[0], y + hs * k3[1], z + hs * k3[2], k4))
                break;
            x += hs / 6.f * (k1[0] + 2.f * (k2[0] + k3[0]) + k4[0]);
            y += hs / 6.f * (k1[1] + 2.f * (k2[1] + k3[1]) + k4[1]);
            z += hs / 6.f * (k1[2] + 2.f * (k2[2] + k3[2]) + k4[2]);
            ++steps;
            const int ni = std::clamp(int(x + 0.5f), 0, t.n[0] - 1), nj = std::clamp(int(y + 0.5f), 0, t.n[1] - 1);
            const int nk = std::clamp(int(z + 0.5f), 0, t.n[2] - 1);
            sum += t.noise[t.at(ni, nj, nk)];
            ++count;
        }
    }
    return sum / float(count);
}

void referenceNaive(benchmark::State& state)
{
    const TightInputs& t = tightInputs();
    std::vector<float> out(t.vx.size());
    std::uint64_t steps = 0;
    CpuTimer cpu{state};
    for (auto _ : state) {
        std::uint64_t perThread[kThreads] = {};
        std::vector<std::thread> threads;
        for (int w = 0; w < kThreads; ++w)
            threads.emplace_back([&, w] {
                std::uint64_t n = 0;
                for (int i = w; i < t.n[0]; i += kThreads)
                    for (int j = 0; j < t.n[1]; ++j)
                        for (int k = 0; k < t.n[2]; ++k) out[t.at(i, j, k)] = tightVoxel(t, i, j, k, n);
                perThread[w] = n;
            });
        for (auto& th : threads) th.join();
        steps = 0;
        for (const auto n : perThread) steps += n;
        benchmark::DoNotOptimize(out.data());
    }
    lic::LicStats stats;
    stats.voxels = out.size();
    report(state, stats);
    state.counters["rk4_steps"] = double(steps);
    // CPU time over steps: the cost of one RK4 step on one core (the yardstick of issue 29).
    state.counters["ns_per_step_core"] = 1e9 * cpu.perIteration() / double(steps);
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

int main(int argc, char** argv)
{
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    // The heap matters to the fast engine's larger bricks (docs/performance.md, 2026-12-05): say
    // which one these figures were taken with.
    benchmark::AddCustomContext("allocator", vdbexport::cli::allocatorDescription());
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}

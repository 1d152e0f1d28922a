// Fast-LIC (Stalling & Hege 1995) in 3D, one brick at a time.
//
// Inside a brick, seeds are taken in scan order from voxels with fewer than min_hits deposits; one
// long streamline is traced from each, the kernel window slides along it (prefix sums or the
// exp recurrence make each window O(1)), and every sample point that lies in an active voxel of
// the brick deposits its window average there. A line runs until it has crossed `coveredRun`
// samples of covered voxels, or leaves the brick, and then n more samples so the windows of its
// last deposits are complete. Voxels are normalised by their deposit weight at the end. The
// accumulators are floats local to the brick and the brick is processed by one thread in a fixed
// order, so the result depends only on the brick (see field/Bricks.h).
//
// Comet loops of spots (LicSettings::comets = N frames): each spot's part of the texture along a
// line is moved to its comets' arcs (the copies of engine/Splat.h CometTables, with the spot's
// phase) and the window slides over each frame's moved texture, so one trace gives every frame
// (docs/technique.md §8).
#pragma once

#include "lic/engine/Driver.h"
#include "lic/engine/Kernels.h"
#include "lic/engine/Settings.h"
#include "lic/engine/Streamline.h"
#include "lic/field/Bricks.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"
#include "lic/util/Buffer.h"
#include "lic/util/Error.h"
#include "lic/util/Progress.h"

#include <openvdb/math/Vec3.h>

#include <algorithm>
#include <atomic>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace lic {

namespace detail {

/// Deposit weight 1/(1 + k|δ|²)², δ = voxel centre − sample (output voxels): 1 at the centre,
/// 0.08 half a voxel away (close to exp(−|δ|²/0.1), without the exp).
constexpr double kDepositFalloff = 10.0;

/// Whether the fast engine traces the next line ahead beside a line's last side (FastLines::
/// traceBrick). The output is the same bits either way; tests turn it off to show that.
inline std::atomic<bool> fastSpeculation{true};

/// Per-thread buffers of the fast engine, reused from brick to brick and line to line: no
/// allocation in the hot path once they have grown.
struct FastScratch
{
    BrickIndex index;                // the brick's local voxel numbering
    std::vector<float> weight;       // per local voxel: Σ deposit weights
    ScratchVector<float> sum;        // per local voxel × K: Σ weight · value (a block's set when ready)
    std::vector<std::uint8_t> sumReady; // per local block: its sums zeroed (at its first deposit)
    std::vector<std::uint8_t> hits;  // per local voxel: deposits, saturating at 255
    std::vector<openvdb::Vec3d> pts; // the RK45 tracer's world positions
    // The line's samples in place: output-index position and local voxel (−1 = not ours) per
    // sample, the seed at the middle, upstream written downwards from it and downstream upwards,
    // so the line is one run of memory without assembling.
    // The buffers of the lines in flight: the line being finished and the next ones, traced
    // speculatively beside it (FastLines::traceBrick).
    static constexpr int kLines = 3;
    std::vector<openvdb::Vec3d> idx[kLines];
    std::vector<std::int64_t> loc[kLines];
    std::vector<double> vals, win, norm, scratch; // samples, window sums, kernel weights
    std::vector<double> moved, movedWin, subNorm; // comet loops: moved texture, its window sums
};

/// The streamlines of one brick of the fast engine: trace from a seed, sample the texture along
/// the line, slide the window, deposit. K output channels (C, or 3C + 2 with Ripple).
template<typename Texture, bool Ripple>
class FastLines
{
public:
    static constexpr int C = Texture::kChannels;
    static constexpr int K = Ripple ? 3 * C + 2 : C;
    // Per sample: C values, then 3·C gradient components (output-index units). With Ripple the
    // same again times cos θ_j and times sin θ_j, then cos θ_j and sin θ_j themselves.
    static constexpr int P = 4 * C;
    static constexpr int W = Ripple ? 3 * P + 2 : P;

    FastLines(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
              const LicSettings& settings, FastScratch& sc);

    /// Trace the line through the voxel `ijk` (local index `seedLocal`) and deposit along it.
    void traceAndDeposit(std::int64_t seedLocal, const openvdb::Coord& ijk);
    /// Every line of the brick: `nextSeed(local, ijk)` gives the next voxel in scan order with
    /// fewer than min_hits deposits (false when there is none). The same lines and deposits as
    /// traceAndDeposit() called for each seed in turn; with RK4, while a line has one side left
    /// the next seed's line is traced beside it speculatively (see the comment in the definition).
    template<typename NextSeed>
    void traceBrick(NextSeed&& nextSeed);
    /// Output channels per voxel: K, or frames · C for a comet loop.
    int channels() const { return mFrames > 0 ? mFrames * C : K; }

    std::uint64_t samples = 0, deposits = 0, streamlines = 0, speculated = 0, dropped = 0;

private:
    /// Per-sample bookkeeping of one side: output-index position and local voxel; decides when
    /// the side has done its job.
    struct Side
    {
        openvdb::Vec3d* idx;     ///< the seed's slot; sample k of the side goes to idx[dir · k]
        std::int64_t* loc;
        std::ptrdiff_t dir;
        std::ptrdiff_t count = 0; ///< samples recorded
        int run = 0, tail = -1;
    };
    /// Local index recorded for a sample outside the brick's box (−1: inside but not ours).
    static constexpr std::int64_t kOutside = -2;
    /// Record a sample at field index `p`; false stops the side.
    bool onSample(Side& st, const openvdb::Vec3d& p);
    /// onSample for the tracer: a side's callback.
    struct SideSink
    {
        FastLines* lines;
        Side* side;
        bool operator()(const openvdb::Vec3d& p) const { return lines->onSample(*side, p); }
    };
    static constexpr int kLines = FastScratch::kLines; ///< lines in flight at most
    /// A line in flight: its two sides' tracer states and sample records, in buffer `buf`.
    struct Line
    {
        detail::IndexSide tb, tf;
        Side back{nullptr, nullptr, -1}, fwd{nullptr, nullptr, 1};
        std::int64_t seed = -1;
        bool live() const { return tb.alive || tf.alive; }
    };
    /// Field index position of an output voxel's centre (output voxel j: field index (j + ½)/K − ½).
    openvdb::Vec3d seedIndex(const openvdb::Coord& ijk) const
    {
        return openvdb::Vec3d((ijk[0] - mUpOff) / mUp, (ijk[1] - mUpOff) / mUp, (ijk[2] - mUpOff) / mUp);
    }
    /// Start `ln` at the seed voxel, its samples in buffer `buf`.
    void startLine(Line& ln, int buf, std::int64_t seedLocal, const openvdb::Coord& ijk);
    /// The traced line's windows and deposits (both sides have ended).
    void finishLine(const Side& back, const Side& fwd, StopReason whyB, StopReason whyF);
    /// A speculative side's stop rule run again over its recorded samples with the deposits as
    /// they are now: the side is cut where onSample would have stopped it, or carries on from the
    /// state onSample would have reached.
    void replay(Side& st, detail::IndexSide& t);
    /// The texture (and ripple products) at every sample, then the window sums.
    void convolveLine(std::size_t N);
    /// Deposit the window averages of samples lo … hi into their voxels.
    void deposit(std::size_t lo, std::size_t hi);
    /// Comet loops: every frame's moved texture along the line (each spot's part at its copies'
    /// arcs, faded near a natural end), then each frame's window sums.
    void convolveComets(std::size_t N, bool endBack, bool endFwd);
    /// Comet loops: deposit every frame's window averages of samples lo … hi.
    void depositComets(std::size_t lo, std::size_t hi);
    /// Voxel s's K sums (K = channels()), its block's zeroed first if no deposit reached it yet.
    float* readySum(std::size_t s)
    {
        constexpr std::size_t V = OutputDomain::kBlockVoxels;
        const std::size_t Kv = std::size_t(channels()), b = s / V;
        if (!sc.sumReady[b]) {
            std::fill_n(sc.sum.data() + b * V * Kv, V * Kv, 0.0f);
            sc.sumReady[b] = 1;
        }
        return sc.sum.data() + s * Kv;
    }
    /// The widest footprint of the texture's channels (a halo's radius): sets the comet spacing.
    static double maxRadius(const Texture& texture);

    const VelocityField& mField;
    const OutputDomain& mDomain;
    const Texture& mTexture;
    const LicSettings& mSettings;
    FastScratch& sc;
    TraceSettings mTrace;
    int mN, mStride;
    double mTheta, mUp, mUpOff;
    std::uint8_t mMinHits;
    bool mOriented;
    // Comet loops (mFrames > 0): the spacing P (output voxels), the fade ramp at a natural end
    // (half a comet), each phase's two copies' arcs in samples and fades.
    int mFrames = 0;
    double mSpacing = 0, mRamp = 0;
    std::vector<double> mCopyShift, mCopyFade; // [phase][copy]
    int mTail; ///< samples traced past the last deposit: n, or n + P/h + 1 for comets
    std::size_t mWinLo = 1, mWinHi = 0; ///< comets: the line's stretch of non-zero windows
    // The traced line: samples 0 … N−1 (upstream end first), in sc.idx / sc.loc.
    const openvdb::Vec3d* mIdx = nullptr;
    const std::int64_t* mLoc = nullptr;
};

} // namespace detail

/// The fast gather engine (see engine/Gather.h for the engine concept).
struct FastEngine
{
    static constexpr EngineType kType = EngineType::Fast;
    static constexpr const char* kStage = "fast LIC";
    static constexpr bool kReportsProgress = false;
    using Scratch = detail::FastScratch;

    /// Fast-LIC of one brick. `out` gets, for each of the brick's blocks in order, K runs of 512
    /// floats (K = C, or 3C + 2 with Ripple: see composite/Animation.h); `stats` is added to.
    /// Gives the same value as the naive engine at every streamline's seed voxel, and window
    /// averages at points within half a voxel of the centre elsewhere.
    template<typename Texture, bool Ripple>
    static void brick(const VelocityField& field, const OutputDomain& domain, const Brick& brick,
                      const Texture& texture, const LicSettings& settings, Scratch& sc, ScratchVector<float>& out,
                      LicStats& stats, Progress& progress);
};

// ------------------------------------------------------------------------------------------

template<typename Texture, bool Ripple>
void FastEngine::brick(const VelocityField& field, const OutputDomain& domain, const Brick& brick,
                       const Texture& texture, const LicSettings& settings, Scratch& sc, ScratchVector<float>& out,
                       LicStats& stats, Progress&)
{
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    sc.index = BrickIndex(domain, brick, brick.box.dim()[0]);
    const BrickIndex& bi = sc.index;
    const std::size_t voxels = bi.voxels();
    detail::FastLines<Texture, Ripple> lines(field, domain, texture, settings, sc);
    const int K = lines.channels();
    sc.weight.assign(voxels, 0.0f);
    // The sums are zeroed a block at a time when a deposit first reaches it (readySum): a brick's
    // box holds N·C floats per voxel in a comet loop (48 MiB at 64³ and 24 frames), most of them
    // in blocks no line reaches or outside the domain.
    if (sc.sum.size() < voxels * std::size_t(K)) sc.sum.resize(voxels * std::size_t(K));
    sc.sumReady.assign(voxels / V, 0);
    sc.hits.assign(voxels, 0);

    // Seeds: every active voxel of the brick in scan order that has fewer than min_hits deposits
    // when the scan reaches it.
    std::size_t bi0 = 0; // the scan: block brick.blocks[bi0], its active voxels from `scanOn`
    auto scanOn = brick.blocks.empty() ? OutputDomain::Mask::OnIterator() : domain.blockMask(brick.blocks[0]).beginOn();
    lines.traceBrick([&](std::int64_t& local, openvdb::Coord& ijk) {
        for (; bi0 < brick.blocks.size(); ++bi0) {
            const std::uint32_t b = brick.blocks[bi0];
            const openvdb::Coord& origin = domain.blockOrigin(b);
            const std::size_t base = bi.localBlock(origin) * V;
            for (; scanOn; ++scanOn) {
                const std::size_t off = scanOn.pos();
                if (sc.hits[base + off] >= std::uint8_t(settings.minHits)) continue;
                ijk = origin + openvdb::Coord(int(off >> 6), int((off >> 3) & 7), int(off & 7));
                local = std::int64_t(base + off);
                ++scanOn;
                return true;
            }
            if (bi0 + 1 < brick.blocks.size()) scanOn = domain.blockMask(brick.blocks[bi0 + 1]).beginOn();
        }
        return false;
    });

    // Normalise into the brick's output blocks: every value of every block is written (0 where no
    // line deposited or the voxel is inactive), so the buffer is not cleared first; it only grows
    // (bricks have different block counts; its growth leaves the new floats unset).
    const std::size_t outSize = brick.blocks.size() * std::size_t(K) * V;
    if (out.size() < outSize) out.resize(outSize);
    for (std::size_t i = 0; i < brick.blocks.size(); ++i) {
        const std::uint32_t b = brick.blocks[i];
        const std::size_t base = bi.localBlock(domain.blockOrigin(b)) * V;
        float* dst = out.data() + i * std::size_t(K) * V;
        std::array<std::uint16_t, V> offs;
        std::array<float, V> invs;
        std::size_t n = 0;
        for (auto on = domain.blockMask(b).beginOn(); on; ++on) {
            const float w = sc.weight[base + on.pos()];
            if (!(w > 0.0f)) continue;
            offs[n] = std::uint16_t(on.pos());
            invs[n++] = 1.0f / w;
        }
        if (n < V) std::fill_n(dst, std::size_t(K) * V, 0.0f);
        detail::writeChannelMajor(
            std::size_t(K), n, [&](std::size_t j) { return std::size_t(offs[j]); },
            [&](std::size_t j, std::size_t k) { return sc.sum[(base + offs[j]) * std::size_t(K) + k] * invs[j]; }, dst);
    }
    stats.samples += lines.samples;
    stats.deposits += lines.deposits;
    stats.streamlines += lines.streamlines;
    stats.speculated += lines.speculated;
    stats.dropped += lines.dropped;
}

namespace detail {

template<typename Texture, bool Ripple>
FastLines<Texture, Ripple>::FastLines(const VelocityField& field, const OutputDomain& domain, const Texture& texture,
                                      const LicSettings& settings, FastScratch& scratch)
    : mField(field)
    , mDomain(domain)
    , mTexture(texture)
    , mSettings(settings)
    , sc(scratch)
    , mTrace(traceSettings(field, domain, settings))
    , mN(settings.halfSamples())
    , mStride(integrationStride(domain, settings))
    , mTheta(rippleStep(settings))
    , mUp(double(domain.upsample()))
    , mUpOff(0.5 * (double(domain.upsample()) - 1.0))
    , mMinHits(std::uint8_t(settings.minHits))
    , mOriented(settings.kernel == KernelType::Exp)
    , mTail(mN)
{
    if (!Ripple && settings.comets > 0) {
        mFrames = settings.comets;
        mSpacing = cometSpacing(settings, maxRadius(texture));
        const double h = settings.step;
        // A voxel's window reads copies of spots up to P away each way (+1 sample: a copy between
        // two samples is shared by both).
        mTail = mN + int(std::ceil(mSpacing / h)) + 1;
        mRamp = 0.5 * double(mOriented ? mN : 2 * mN) * h + maxRadius(texture) + 0.5;
        for (int g = 0; g < mFrames; ++g)
            for (int m = 0; m < 2; ++m) {
                const double a = (double(g) / double(mFrames) - double(m)) * mSpacing;
                mCopyShift.push_back(a / h);
                mCopyFade.push_back(cometFade(a, mSpacing));
            }
    }
    const double maxLen = settings.maxStreamline > 0 ? settings.maxStreamline : std::max(8.0 * settings.length, 200.0);
    mTrace.maxSamples = std::max(2 * mTail + settings.coveredRun, int(std::lround(maxLen / settings.step)));
}

template<typename Texture, bool Ripple>
double FastLines<Texture, Ripple>::maxRadius(const Texture& texture)
{
    if constexpr (requires(const Texture& t) { t.radius(0); }) {
        double r = 0;
        for (int c = 0; c < C; ++c) r = std::max(r, texture.radius(c));
        return r;
    } else {
        throw InputError("comet loops need spot input");
    }
}

template<typename Texture, bool Ripple>
bool FastLines<Texture, Ripple>::onSample(Side& st, const openvdb::Vec3d& p)
{
    // Output index q of field index p: output voxel j has its centre at field index (j + ½)/K − ½.
    const openvdb::Vec3d q(p[0] * mUp + mUpOff, p[1] * mUp + mUpOff, p[2] * mUp + mUpOff);
    const openvdb::Coord ijk = OutputDomain::nearestVoxel(q);
    std::int64_t l = sc.index.localOf(ijk);
    if (l < 0 && !sc.index.inside(ijk)) l = kOutside;
    ++st.count;
    st.idx[st.dir * st.count] = q;
    st.loc[st.dir * st.count] = l;
    if (st.tail >= 0) return --st.tail > 0;
    if (l == kOutside) {
        // Left the brick: trace on only to complete the windows of the samples inside.
        st.tail = mTail - 1;
        return st.tail > 0;
    }
    st.run = (l < 0 || sc.hits[std::size_t(l)] >= mMinHits) ? st.run + 1 : 0;
    if (st.run >= mSettings.coveredRun) st.tail = mTail; // finish the window, then stop
    return true;
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::replay(Side& st, detail::IndexSide& t)
{
    // onSample's decisions again, from the recorded local indices and today's hits.
    int run = 0, tail = -1;
    for (std::ptrdiff_t k = 1; k <= st.count; ++k) {
        const std::int64_t l = st.loc[st.dir * k];
        bool more = true;
        if (tail >= 0) {
            more = --tail > 0;
        } else if (l == kOutside) {
            tail = mTail - 1;
            more = tail > 0;
        } else {
            run = (l < 0 || sc.hits[std::size_t(l)] >= mMinHits) ? run + 1 : 0;
            if (run >= mSettings.coveredRun) tail = mTail;
        }
        if (!more) {
            st.count = k;
            st.run = run;
            st.tail = tail;
            t.alive = false;
            t.why = StopReason::Caller;
            return;
        }
    }
    // Deposits only ever add hits, so the rule stops a side no later than it did before them.
    if (!t.alive && t.why == StopReason::Caller)
        throw std::logic_error("fast engine: a speculative line's replay ran past where it stopped");
    st.run = run;
    st.tail = tail;
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::startLine(Line& ln, int buf, std::int64_t seedLocal, const openvdb::Coord& ijk)
{
    // Each side records at most maxSamples samples (the tracer stops it there).
    const std::size_t M = std::size_t(mTrace.maxSamples);
    if (sc.idx[buf].size() < 2 * M + 1) {
        sc.idx[buf].resize(2 * M + 1);
        sc.loc[buf].resize(2 * M + 1);
    }
    openvdb::Vec3d* mid = sc.idx[buf].data() + M;
    std::int64_t* midLoc = sc.loc[buf].data() + M;
    *mid = ijk.asVec3d();
    *midLoc = seedLocal;
    ln.back = Side{mid, midLoc, -1};
    ln.fwd = Side{mid, midLoc, +1};
    ln.seed = seedLocal;
    const openvdb::Vec3d seedIdx = seedIndex(ijk);
    ln.tb = detail::startSide(mField, seedIdx, -1.0, mTrace.minSpeed);
    ln.tf = detail::startSide(mField, seedIdx, +1.0, mTrace.minSpeed);
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::traceAndDeposit(std::int64_t seedLocal, const openvdb::Coord& ijk)
{
    Line ln;
    startLine(ln, 0, seedLocal, ijk);
    const auto [whyB, whyF] = traceIndexPair(
        mField, seedIndex(ijk), mTrace, mStride, sc.pts, [&](const openvdb::Vec3d& p) { return onSample(ln.back, p); },
        [&](const openvdb::Vec3d& p) { return onSample(ln.fwd, p); });
    finishLine(ln.back, ln.fwd, whyB, whyF);
}

// Speculation. While a line has one side left (a lone side: its other side stopped in covered
// voxels), the next seed in scan order is taken with the hits as they are before this line's
// deposits, and its line is traced beside the lone side, their RK4 stages interleaved
// (stepLanes) so the CPU overlaps their latency chains. When the first line has deposited:
// if the next seed is now covered, the sequential scan would have skipped it, so its line is
// dropped and the scan goes on after it; otherwise the sequential scan would have picked it
// (the voxels between were covered before and hits only grow), its trace is the same (tracing
// does not read hits), and only where its sides stop can differ: the stop rule is replayed on its
// recorded samples with the new hits (replay()), cutting each side where onSample would have
// stopped it. So the lines, their samples and their deposits are exactly the sequential ones.
template<typename Texture, bool Ripple>
template<typename NextSeed>
void FastLines<Texture, Ripple>::traceBrick(NextSeed&& nextSeed)
{
    std::int64_t local = 0;
    openvdb::Coord ijk;
    if (mTrace.integrator != Integrator::RK4 || !fastSpeculation.load(std::memory_order_relaxed)) {
        while (nextSeed(local, ijk)) traceAndDeposit(local, ijk);
        return;
    }
    using detail::IndexSide;
    // q[0] is the line being finished: every earlier line has deposited. q[1 …] are speculative,
    // in scan order. Each has its own buffer (sc.idx[b], sc.loc[b]).
    Line lines[kLines];
    int q[kLines];
    int qn = 0;
    bool seedsLeft = true;
    const int stride = std::max(1, mStride);
    auto push = [&] {
        int b = 0;
        while (std::find(q, q + qn, b) != q + qn) ++b;
        startLine(lines[b], b, local, ijk);
        q[qn++] = b;
    };
    auto pop = [&] { std::copy(q + 1, q + qn--, q); };
    for (;;) {
        if (qn == 0) {
            if (!seedsLeft || !nextSeed(local, ijk)) break;
            push();
        }
        int live = 0;
        for (int i = 0; i < qn; ++i) live += int(lines[q[i]].tb.alive) + int(lines[q[i]].tf.alive);
        if (live == 1 && qn < kLines && seedsLeft) {
            if (nextSeed(local, ijk)) {
                push();
                ++speculated;
            } else {
                seedsLeft = false;
            }
        }
        // One step of every live side, their RK4 stages interleaved.
        IndexSide* sides[2 * kLines];
        SideSink sinks[2 * kLines];
        SideSink* sinkPtrs[2 * kLines];
        int n = 0;
        for (int i = 0; i < qn; ++i) {
            Line& ln = lines[q[i]];
            sides[n] = &ln.tb, sinks[n] = SideSink{this, &ln.back}, sinkPtrs[n] = &sinks[n], ++n;
            sides[n] = &ln.tf, sinks[n] = SideSink{this, &ln.fwd}, sinkPtrs[n] = &sinks[n], ++n;
        }
        detail::stepSides(mField, sides, sinkPtrs, n, mTrace, stride);
        // Finish the lines at the front that have ended; each line behind one becomes the front
        // once it has deposited: dropped if its seed is now covered, else its stop rule replayed.
        while (qn > 0 && !lines[q[0]].live()) {
            const Line& f = lines[q[0]];
            finishLine(f.back, f.fwd, f.tb.why, f.tf.why);
            pop();
            while (qn > 0) {
                Line& next = lines[q[0]];
                if (sc.hits[std::size_t(next.seed)] < mMinHits) {
                    replay(next.back, next.tb);
                    replay(next.fwd, next.tf);
                    break;
                }
                ++dropped;
                pop();
            }
        }
    }
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::finishLine(const Side& back, const Side& fwd, StopReason whyB, StopReason whyF)
{
    auto natural = [](StopReason why) { return why == StopReason::Boundary || why == StopReason::ZeroVelocity; };
    const std::size_t B = std::size_t(back.count), N = B + 1 + std::size_t(fwd.count);
    mIdx = back.idx - back.count;
    mLoc = back.loc - back.count;
    // Samples whose window runs past an artificial end (length limit, early stop, brick exit)
    // are not deposited; near a natural end the window is truncated exactly as in the naive
    // engine. The exp kernel only looks downstream, so the upstream end never cuts a window;
    // comets come from up to P either way.
    const std::size_t n = std::size_t(mTail);
    const std::size_t lo = (natural(whyB) || (mOriented && mFrames == 0)) ? 0 : std::min(B, n);
    const std::size_t hi = natural(whyF) ? N - 1 : std::max(B, N - 1 - std::min(N - 1, n));
    if (mFrames > 0) {
        convolveComets(N, natural(whyB), natural(whyF));
        depositComets(lo, hi);
    } else {
        convolveLine(N);
        deposit(lo, hi);
    }
    samples += N;
    ++streamlines;
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::convolveLine(std::size_t N)
{
    sc.vals.resize(N * W);
    sc.win.resize(N * W);
    sc.norm.resize(N);
    float v[P];
    for (std::size_t i = 0; i < N; ++i) {
        mTexture.sampleGradient(mIdx[i], v, v + C);
        double* o = &sc.vals[i * W];
        for (int c = 0; c < P; ++c) o[c] = v[c];
        if constexpr (Ripple) {
            const double cs = std::cos(mTheta * double(i)), sn = std::sin(mTheta * double(i));
            for (int c = 0; c < P; ++c) {
                o[P + c] = v[c] * cs;
                o[2 * P + c] = v[c] * sn;
            }
            o[3 * P] = cs;
            o[3 * P + 1] = sn;
        }
    }
    windowSums(mSettings.kernel, mSettings.decay, mN, N, W, sc.vals.data(), sc.win.data(), sc.norm.data(), sc.scratch);
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::deposit(std::size_t lo, std::size_t hi)
{
    // Runs of samples share a kernel weight (all but the windows cut by a natural end), so its
    // reciprocal is taken once per run: the same value, without a division per deposit.
    double norm = 0.0, inv = 0.0;
    for (std::size_t i = lo; i <= hi; ++i) {
        const std::int64_t l = mLoc[i];
        if (l < 0) continue;
        if (sc.norm[i] != norm) {
            norm = sc.norm[i];
            inv = 1.0 / norm;
        }
        // First-order correction from the sample point to the voxel centre: the window average of
        // the texture gradient applied to the offset δ (the streamline through the centre is, to
        // first order, this one shifted by δ). Deposits are weighted by 1/(1 + 10|δ|²)², so passes
        // near the centre dominate a voxel's average.
        const openvdb::Vec3d off = OutputDomain::nearestVoxel(mIdx[i]).asVec3d() - mIdx[i];
        const double r2 = 1.0 + off.lengthSqr() * kDepositFalloff;
        const double w = 1.0 / (r2 * r2);
        const double* Wi = &sc.win[i * W];
        double o[K];
        for (int c = 0; c < C; ++c) {
            const double* g = Wi + C + 3 * c;
            o[c] = (Wi[c] + g[0] * off[0] + g[1] * off[1] + g[2] * off[2]) * inv;
        }
        if constexpr (Ripple) {
            // Window sums relative to sample i: rotate Σ_j x_j e^{iθj} by e^{−iθi} (cos θ_i and
            // sin θ_i are stored with the sample).
            const double cs = sc.vals[i * W + 3 * P], sn = sc.vals[i * W + 3 * P + 1];
            const double* Rc = Wi + P;
            const double* Rs = Wi + 2 * P;
            auto re = [&](int k) { return Rc[k] * cs + Rs[k] * sn; };
            auto im = [&](int k) { return Rs[k] * cs - Rc[k] * sn; };
            for (int c = 0; c < C; ++c) {
                const int g = C + 3 * c;
                o[C + c] = (re(c) + re(g) * off[0] + re(g + 1) * off[1] + re(g + 2) * off[2]) * inv;
                o[2 * C + c] = (im(c) + im(g) * off[0] + im(g + 1) * off[1] + im(g + 2) * off[2]) * inv;
            }
            const double nc = Wi[3 * P], ns = Wi[3 * P + 1];
            o[3 * C] = (nc * cs + ns * sn) * inv;
            o[3 * C + 1] = (ns * cs - nc * sn) * inv;
        }
        const std::size_t s = std::size_t(l);
        float* acc = readySum(s);
        for (int k = 0; k < K; ++k) acc[k] += float(w * o[k]);
        sc.weight[s] += float(w);
        if (sc.hits[s] < 255) ++sc.hits[s];
        ++deposits;
    }
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::convolveComets(std::size_t N, bool endBack, bool endFwd)
{
    if constexpr (requires(const Texture& t, const openvdb::Vec3d& p) {
                      t.centre(0u);
                      t.forEachSpot(p, [](std::uint32_t, const float*, const float*) {});
                  }) { // spot textures
        // Sample-major: row i holds every frame's P values (frame f at f·P), so one pass of the
        // window sums serves every frame. Only rows some copy reached are non-zero; they are
        // cleared again after use, so the array is zeroed once, not per line.
        const std::size_t F = std::size_t(mFrames), Wf = F * std::size_t(P);
        if (sc.moved.size() < N * Wf) sc.moved.resize(N * Wf, 0.0);
        sc.norm.resize(N);
        windowSums(mSettings.kernel, mSettings.decay, mN, N, 0, nullptr, nullptr, sc.norm.data(), sc.scratch);
        const double h = mSettings.step;
        // Natural ends lie half a step past the end samples; a copy nearing one fades out over
        // half a comet (copies past it do not exist), as in the splat engine.
        const double back = endBack ? -0.5 : -1e300, fwd = endFwd ? double(N) - 0.5 : 1e300;
        std::size_t lo = N, hi = 0;
        for (std::size_t i = 0; i < N; ++i) {
            mTexture.forEachSpot(mIdx[i], [&](std::uint32_t s, const float* v, const float* g) {
                const std::size_t phase = std::size_t(cometPhase(mTexture.centre(s), mFrames));
                for (std::size_t f = 0; f < F; ++f) {
                    const std::size_t ph = (f + phase) % F;
                    for (std::size_t m = 0; m < 2; ++m) {
                        double amp = mCopyFade[2 * ph + m];
                        if (!(amp > 0)) continue;
                        const double j = double(i) + mCopyShift[2 * ph + m];
                        if (endBack || endFwd) amp *= std::clamp(std::min(fwd - j, j - back) * h / mRamp, 0.0, 1.0);
                        if (!(amp > 0)) continue;
                        // Shared by the two samples around arc j, linearly.
                        const double j0 = double(detail::floorIndex(j)), t = j - j0;
                        for (int e = 0; e < 2; ++e) {
                            const double at = j0 + double(e), w = amp * (e ? t : 1.0 - t);
                            if (at < 0 || at >= double(N) || w == 0) continue;
                            const std::size_t r = std::size_t(at);
                            lo = std::min(lo, r);
                            hi = std::max(hi, r);
                            double* o = &sc.moved[r * Wf + f * std::size_t(P)];
                            for (int c = 0; c < C; ++c) o[c] += w * v[c];
                            for (int c = 0; c < 3 * C; ++c) o[C + c] += w * g[c];
                        }
                    }
                }
            });
        }
        if (lo > hi) { // no copy on this line: every frame's windows are 0
            mWinLo = 1;
            mWinHi = 0;
            return;
        }
        // Windows are zero outside lo − n … hi + n; summed over that stretch alone they are the
        // same numbers as over the whole line (the rows beyond are exact zeros).
        const std::size_t n = std::size_t(mN);
        mWinLo = lo >= n ? lo - n : 0;
        mWinHi = std::min(N - 1, hi + n);
        const std::size_t M = mWinHi - mWinLo + 1;
        sc.movedWin.resize(M * Wf);
        sc.subNorm.resize(M);
        windowSums(mSettings.kernel, mSettings.decay, mN, M, int(Wf), &sc.moved[mWinLo * Wf], sc.movedWin.data(),
                   sc.subNorm.data(), sc.scratch);
        std::fill(sc.moved.begin() + std::ptrdiff_t(lo * Wf), sc.moved.begin() + std::ptrdiff_t((hi + 1) * Wf), 0.0);
    } else {
        (void)N, (void)endBack, (void)endFwd;
        throw InputError("comet loops need spot input");
    }
}

template<typename Texture, bool Ripple>
void FastLines<Texture, Ripple>::depositComets(std::size_t lo, std::size_t hi)
{
    const std::size_t F = std::size_t(mFrames), Wf = F * std::size_t(P);
    for (std::size_t i = lo; i <= hi; ++i) {
        const std::int64_t l = mLoc[i];
        if (l < 0) continue;
        const std::size_t s = std::size_t(l);
        float* acc = readySum(s); // also where every window is 0: the voxel's weight grows below
        // As deposit(): the first-order correction to the voxel centre, proximity-weighted.
        const openvdb::Vec3d off = OutputDomain::nearestVoxel(mIdx[i]).asVec3d() - mIdx[i];
        const double r2 = 1.0 + off.lengthSqr() * kDepositFalloff;
        const double w = 1.0 / (r2 * r2);
        if (i >= mWinLo && i <= mWinHi) { // elsewhere every frame's window is 0
            const double inv = 1.0 / sc.norm[i];
            const double* Wr = &sc.movedWin[(i - mWinLo) * Wf];
            for (std::size_t f = 0; f < F; ++f) {
                const double* Wi = Wr + f * std::size_t(P);
                for (int c = 0; c < C; ++c) {
                    const double* g = Wi + C + 3 * c;
                    acc[f * std::size_t(C) + std::size_t(c)] +=
                        float(w * (Wi[c] + g[0] * off[0] + g[1] * off[1] + g[2] * off[2]) * inv);
                }
            }
        }
        sc.weight[s] += float(w);
        if (sc.hits[s] < 255) ++sc.hits[s];
        ++deposits;
    }
}

} // namespace detail
} // namespace lic

#include "lic/composite/Compositor.h"

#include "lic/composite/Animation.h"
#include "lic/field/Region.h"
#include "lic/util/Error.h"
#include "lic/util/Parallel.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

namespace lic {

namespace {
using FloatLeaf = openvdb::FloatTree::LeafNodeType;

/// A scalar's value mapped from `range` onto [0, 1], clamped.
double unitOf(float v, const std::array<double, 2>& range)
{
    return std::clamp((double(v) - range[0]) / (range[1] - range[0]), 0.0, 1.0);
}

/// Texture channel c of loop frame f (1-based) from a voxel's raw channels: composed from the
/// ripple sums, or read directly from a comet loop's frame-major channels.
template<typename Raw>
float loopFrameValue(const CompositeSettings& s, const Raw& raw, int c, int f, const FramePhase& ph)
{
    const int C = s.textureChannels();
    if (s.comets) return raw((f - 1) * C + c);
    return rippleFrameValue(raw(c), raw(C + c), raw(2 * C + c), raw(3 * C), raw(3 * C + 1), ph);
}
} // namespace

Compositor::Compositor(const CompositeSettings& settings, CompositeInputs inputs, const VelocityField& field,
                       const OutputDomain& domain, const BrickLayout& layout)
    : mSettings(settings)
    , mInputs(std::move(inputs))
    , mField(field)
    , mDomain(domain)
{
    const CompositeSettings& s = mSettings;
    if (mInputs.color && !mInputs.colormap) throw InputError("colour by a scalar needs a colormap");
    if (s.writes(OutputGrid::Input) && !(s.spots ? mInputs.spots != nullptr : mInputs.noise != nullptr))
        throw InputError("writing the input grid needs the input texture");
    const std::size_t blocks = domain.blockCount();
    if (!s.composesOnArrival()) {
        mRawLeaves.resize(std::size_t(s.rawChannels()));
        for (auto& set : mRawLeaves) set.init(blocks);
        if (s.spots && mInputs.width && s.levels > 1) mWidthLeaves.init(blocks);
        if (mInputs.roi) mRoiLeaves.init(blocks);
    } else if (s.frames > 1) {
        mLoopBlocks.resize(blocks);
    } else {
        mStill.density.init(blocks);
        mStill.halo.init(blocks);
        if (s.series()) {
            mStill.lines.resize(std::size_t(s.levels));
            mStill.halos.resize(std::size_t(s.levels));
            for (auto& set : mStill.lines) set.init(blocks);
            for (auto& set : mStill.halos) set.init(blocks);
        }
    }
    for (const OutputGridRow& row : outputGrids()) {
        if (row.perFrame || !writes(row)) continue;
        if (row.type == "vec3s") vectors(row.id).init(blocks);
        else floats(row.id).init(blocks);
    }
    if (s.spots && s.writes(OutputGrid::Input)) mInputSpots.emplace(*mInputs.spots, std::array<double, 1>{s.inputRadius}, s.haloScale);
    mMoments.assign(layout.size(), Moments{});
    for (int f = 1; f <= s.frames; ++f) mPhases.emplace_back(f, s.frames);
    for (int k = 0; k < s.levels; ++k) {
        mMaxInvPeak = std::max(mMaxInvPeak, float(1.0 / s.linePeak[std::size_t(k)]));
        mMaxInvPeak = std::max(mMaxInvPeak, float(1.0 / s.haloPeak[std::size_t(k)]));
    }
}

template<typename Raw>
Compositor::SpotVoxel Compositor::composeSpots(const Raw& raw, float widthT, float roi) const
{
    const int K = mSettings.levels;
    SpotVoxel v;
    for (int k = 0; k < K; ++k) {
        const float li = float(1.0 / mSettings.linePeak[std::size_t(k)]);
        const float hi = float(1.0 / mSettings.haloPeak[std::size_t(k)]);
        v.lines[k] = std::clamp(raw(k) * li, 0.0f, 1.0f);
        v.halos[k] = std::max(std::clamp(raw(K + k) * hi, 0.0f, 1.0f), v.lines[k]); // halo ⊇ line
    }
    if (mInputs.width && K > 1) {
        // Blend the two levels around t·(K − 1): continuous in t, so no seams.
        const double u = double(widthT) * double(K - 1);
        const int k0 = std::min(K - 2, int(u));
        const float w = float(u - k0);
        v.density = (1.0f - w) * v.lines[k0] + w * v.lines[k0 + 1];
        v.halo = (1.0f - w) * v.halos[k0] + w * v.halos[k0 + 1];
    } else {
        v.density = v.lines[0];
        v.halo = v.halos[0];
    }
    if (mInputs.roi) {
        v.density *= roi;
        v.halo *= roi;
        for (int k = 0; k < K; ++k) {
            v.lines[k] *= roi;
            v.halos[k] *= roi;
        }
    }
    return v;
}

template<typename Fn>
void Compositor::forEachStillSet(Fn&& fn)
{
    // The names and order of frame() for a still composed on arrival, then buildStatic()'s. Each
    // name is made only when asked for (sealLeaves), not on every brick's hand-over.
    int g = 0;
    const auto named = [](OutputGrid id, int level = 0) { return [id, level] { return outputGridName(id, level); }; };
    fn(g++, named(OutputGrid::Density), mStill.density);
    fn(g++, named(OutputGrid::Halo), mStill.halo);
    for (std::size_t k = 0; k < mStill.lines.size(); ++k) {
        fn(g++, named(OutputGrid::LevelLines, int(k + 1)), mStill.lines[k]);
        fn(g++, named(OutputGrid::LevelHalos, int(k + 1)), mStill.halos[k]);
    }
    forEachShared([&](const OutputGridRow& row, auto& set) { fn(g++, named(row.id), set); });
}

template<typename Fn>
void Compositor::forEachShared(Fn&& fn)
{
    // The constructor enabled the set of the row's type, or none.
    for (const OutputGridRow& row : outputGrids()) {
        if (row.perFrame) continue;
        SharedLeaves& set = mShared[std::size_t(row.id)];
        if (set.vectors.enabled()) fn(row, set.vectors);
        else if (set.floats.enabled()) fn(row, set.floats);
    }
}

bool Compositor::writes(const OutputGridRow& row) const
{
    switch (row.when) {
    case GridWhen::Always: return true;
    case GridWhen::Spots: return mSettings.spots;
    case GridWhen::Asked: return mSettings.grids.has(row.id) && (!row.perLevel || mSettings.spots);
    case GridWhen::ColorScalar: return bool(mInputs.color);
    }
    return false;
}

bool Compositor::sealLeaves(LeafSealer* sealer)
{
    // A spot still: every grid. A loop: the grids every frame shares (colour, scalar, tangent...),
    // final when their brick is consumed, so compressed once for all the frames instead of once
    // per frame file; a comet loop also every frame's own grids (density, halo, levels), composed
    // as the bricks arrive (keepLoopBlock). A gather engine's still composes its grids at the end:
    // nothing.
    if (!sealer) return false;
    const bool still = mSettings.composesOnArrival() && mSettings.frames == 1;
    if (!still && mSettings.frames == 1) return false;
    const bool comets = !still && !mLoopBlocks.empty();
    std::vector<std::string> names;
    if (still) forEachStillSet([&](int, const auto& name, const auto&) { names.push_back(name()); });
    if (comets)
        for (int v = 0; v < loopValues(); ++v) names.push_back(loopValueName(v));
    if (!still) forEachShared([&](const OutputGridRow& row, const auto&) { names.push_back(std::string(row.name)); });
    if (names.empty()) return false;
    sealer->begin(names, comets ? mSettings.frames : 1);
    mSealer = sealer;
    mSealFrames = comets;
    return true;
}

std::string Compositor::loopValueName(int v) const
{
    // loopValues()' order: density, halo, each level's lines, each level's halos.
    const int K = mSettings.levels;
    if (v < 2) return outputGridName(v == 0 ? OutputGrid::Density : OutputGrid::Halo);
    if (v < 2 + K) return outputGridName(OutputGrid::LevelLines, v - 2 + 1);
    return outputGridName(OutputGrid::LevelHalos, v - 2 - K + 1);
}

void Compositor::consume(const BrickChannels& bc)
{
    Moments moments;
    for (std::size_t i = 0; i < bc.brick->blocks.size(); ++i)
        if (!bc.blockTouched || bc.blockTouched[i]) consumeBlock(bc, i, moments);
    mMoments[bc.index] = moments;
    if (!mSealer) return;
    // The brick owns its blocks: their leaves are final.
    for (std::size_t i = 0; i < bc.brick->blocks.size(); ++i) {
        if (bc.blockTouched && !bc.blockTouched[i]) continue;
        const std::size_t b = bc.brick->blocks[i];
        if (mSettings.frames > 1) { // a loop: the shared grids (and its frames' in keepLoopBlock)
            int g = mSealFrames ? loopValues() : 0; // a comet loop's frame grids come first
            forEachShared([&](const OutputGridRow&, auto& set) { set.seal(b, *mSealer, g++); });
        } else {
            forEachStillSet([&](int g, const auto&, auto& set) { set.seal(b, *mSealer, g); });
        }
    }
}

void Compositor::consumeBlock(const BrickChannels& bc, std::size_t i, Moments& moments)
{
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    const CompositeSettings& s = mSettings;
    const std::size_t b = bc.brick->blocks[i];
    const openvdb::Coord origin = mDomain.blockOrigin(b);
    const int frames = s.frames;
    const NoiseTexture* noise = (!s.spots && s.writes(OutputGrid::Input)) ? &(*mInputs.noise)(*bc.brick) : nullptr;

    // Spots composed on arrival (stills, comet loops): most voxels a footprint touches show in no
    // frame; rule them out from their largest raw value before looking up scalars and composing.
    // Every composed value is a clamped, blended (convex) mix of raw × 1/peak ≤ that bound, times
    // roi ≤ 1; the 0.99 keeps float rounding of the blend from reaching the threshold, so a voxel
    // is ruled out only where keepSpotVoxel would drop it too.
    const int boundChannels = s.spots && s.composesOnArrival() ? frames * s.textureChannels() : 0;
    // A comet loop gathers the voxels the bound leaves (candidates) and composes them afterwards,
    // frame by frame (composeLoopBlock), so each raw channel is read as one run.
    thread_local LoopStage stage;
    LoopStage* loop = mLoopBlocks.empty() ? nullptr : &stage;
    if (loop) stage.candidates = 0;
    // The bound of every voxel of the block at once, a channel's run of 512 at a time (per voxel, the
    // channels lie 2 KiB apart: 48 of them in a 24-frame loop).
    thread_local std::array<float, V> top;
    if (boundChannels > 0) {
        std::copy_n(bc.block(i, 0), V, top.begin());
        for (int c = 1; c < boundChannels; ++c) {
            const float* run = bc.block(i, c);
            for (std::size_t v = 0; v < V; ++v) top[v] = std::max(top[v], run[v]);
        }
    }
    std::optional<ScalarField::BlockSampler> widthAt, roiAt;
    if (mInputs.width) widthAt.emplace(mInputs.width, mDomain).setBlock(origin);
    if (mInputs.roi) roiAt.emplace(mInputs.roi, mDomain).setBlock(origin);
    for (auto on = mDomain.blockMask(b).beginOn(); on; ++on) {
        const openvdb::Index off = on.pos();
        auto raw = [&](int c) { return bc.block(i, c)[off]; };
        if (boundChannels > 0 && top[off] * mMaxInvPeak <= 0.99f * kSparseEpsilon) continue;
        float widthT = 0.0f;
        if (widthAt) {
            const double t = unitOf(widthAt->at(off), s.widthRange);
            widthT = float(s.widthInvert ? 1.0 - t : t);
        }
        const float roi = roiAt ? roiWeight(roiAt->at(off), s.roiRange[0], s.roiRange[1]) : 1.0f;
        if (loop) {
            const std::uint32_t j = stage.candidates++;
            stage.off[j] = std::uint16_t(off);
            stage.widthT[j] = widthT;
            stage.roi[j] = roi;
            continue;
        }
        if (s.spots) {
            if (!keepSpotVoxel(raw, widthT, roi, b, origin, off)) continue;
        } else {
            moments.add(frames > 1 ? rippleFrameValue(raw(0), raw(1), raw(2), raw(3), raw(4), mPhases[0])
                                   : raw(0));
        }
        keepVoxel(bc, i, b, origin, off, widthT, roi, noise);
    }
    if (loop && stage.candidates > 0) {
        composeLoopBlock(bc, i, stage);
        // The kept voxels' other grids, in voxel order as a still's.
        for (std::uint32_t j = 0; j < stage.candidates; ++j)
            if (stage.shows[j]) keepVoxel(bc, i, b, origin, stage.off[j], stage.widthT[j], stage.roi[j], noise);
        keepLoopBlock(b, stage);
    }
}

void Compositor::keepVoxel(const BrickChannels& bc, std::size_t i, std::size_t b, const openvdb::Coord& origin,
                           openvdb::Index off, float widthT, float roi, const NoiseTexture* noise)
{
    constexpr std::size_t V = OutputDomain::kBlockVoxels;
    if (!mRawLeaves.empty()) {
        for (int c = 0; c < mSettings.rawChannels(); ++c)
            mRawLeaves[std::size_t(c)].leaf(b, origin).setValueOn(off, bc.block(i, c)[off]);
        if (mWidthLeaves.enabled()) mWidthLeaves.leaf(b, origin).setValueOn(off, widthT);
        if (mRoiLeaves.enabled()) mRoiLeaves.leaf(b, origin).setValueOn(off, roi);
    }
    addStatic(b, origin, off, mDomain.coordOf(b * V + off), noise);
}

void Compositor::composeLoopBlock(const BrickChannels& bc, std::size_t i, LoopStage& stage) const
{
    // Every frame of every candidate composed once, frame-major ([frame][value][candidate]); a
    // candidate is kept when line or halo shows in some frame, so every frame file has the same
    // topology.
    const int frames = mSettings.frames, K = mSettings.levels, series = mSettings.series() ? K : 0;
    const std::size_t nc = stage.candidates, per = std::size_t(loopValues());
    stage.values.resize(std::size_t(frames) * per * nc);
    std::fill_n(stage.shows.begin(), nc, std::uint8_t(0));
    for (int f = 1; f <= frames; ++f) {
        const FramePhase& ph = mPhases[std::size_t(f - 1)];
        float* out = stage.values.data() + std::size_t(f - 1) * per * nc;
        for (std::size_t j = 0; j < nc; ++j) {
            const openvdb::Index off = stage.off[j];
            auto raw = [&](int c) { return bc.block(i, c)[off]; };
            const SpotVoxel sv = composeSpots([&](int c) { return loopFrameValue(mSettings, raw, c, f, ph); },
                                              stage.widthT[j], stage.roi[j]);
            stage.shows[j] |= std::uint8_t(showsIn(sv));
            out[j] = sv.density;
            out[nc + j] = sv.halo;
            for (int k = 0; k < series; ++k) {
                out[std::size_t(2 + k) * nc + j] = sv.lines[k];
                out[std::size_t(2 + K + k) * nc + j] = sv.halos[k];
            }
        }
    }
}

void Compositor::keepLoopBlock(std::size_t b, const LoopStage& stage)
{
    // The shown candidates' columns of every frame's values: frame-major, one contiguous run per
    // frame and value.
    const std::size_t nc = stage.candidates, rows = std::size_t(mSettings.frames * loopValues());
    std::size_t n = 0;
    LoopBlock& lb = mLoopBlocks[b];
    lb.kept.setOff();
    for (std::size_t j = 0; j < nc; ++j)
        if (stage.shows[j]) {
            lb.kept.setOn(stage.off[j]);
            ++n;
        }
    lb.count = std::uint32_t(n);
    if (n == 0) return;
    if (mSealFrames) {
        sealLoopBlock(b, stage, lb);
        return;
    }
    lb.values = std::make_unique_for_overwrite<float[]>(n * rows);
    for (std::size_t r = 0; r < rows; ++r) {
        const float* row = stage.values.data() + r * nc;
        float* dst = lb.values.get() + r * n;
        for (std::size_t j = 0; j < nc; ++j)
            if (stage.shows[j]) *dst++ = row[j];
    }
}

void Compositor::sealLoopBlock(std::size_t b, const LoopStage& stage, LoopBlock& lb)
{
    // Each frame's and value's leaf as composeLoopLeaves would make it (the kept voxels' values
    // on, every other value 0), handed to the sealer at once: one scratch leaf, the same voxels
    // set in every row.
    const std::size_t nc = stage.candidates, per = std::size_t(loopValues());
    const std::size_t rows = std::size_t(mSettings.frames) * per;
    thread_local FloatLeaf leaf;
    leaf.setOrigin(mDomain.blockOrigin(b));
    leaf.fill(0.0f, false);
    leaf.setValueMask(lb.kept);
    float* data = leaf.buffer().data();
    lb.tags = std::make_unique_for_overwrite<std::uint32_t[]>(rows);
    for (std::size_t r = 0; r < rows; ++r) {
        const float* row = stage.values.data() + r * nc;
        for (std::size_t j = 0; j < nc; ++j)
            if (stage.shows[j]) data[stage.off[j]] = row[j];
        lb.tags[r] = mSealer->seal(int(r % per), leaf, int(r / per)); // r = frame · per + value
    }
}

void Compositor::composeLoopLeaves(int f, LeafSet<openvdb::FloatGrid>& density, LeafSet<openvdb::FloatGrid>& halo,
                                   std::vector<LeafSet<openvdb::FloatGrid>>& lines,
                                   std::vector<LeafSet<openvdb::FloatGrid>>& halos)
{
    const std::size_t K = std::size_t(mSettings.levels), per = std::size_t(loopValues());
    const ThreadLimit threadLimit(mSettings.threads);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mDomain.blockCount()), [&](const auto& range) {
        for (std::size_t b = range.begin(); b != range.end(); ++b) {
            const LoopBlock& lb = mLoopBlocks[b];
            if (lb.count == 0) continue;
            const openvdb::Coord origin = mDomain.blockOrigin(b);
            if (lb.tags) { // sealed (sealLoopBlock): the frame's topology-only leaves
                const std::uint32_t* tags = lb.tags.get() + std::size_t(f - 1) * per;
                auto put = [&](LeafSet<openvdb::FloatGrid>& set, std::size_t v) {
                    set.put(b, topologyOnly<FloatLeaf>(origin, lb.kept, tags[v]));
                };
                put(density, 0);
                put(halo, 1);
                for (std::size_t k = 0; k < lines.size(); ++k) {
                    put(lines[k], 2 + k);
                    put(halos[k], 2 + K + k);
                }
                continue;
            }
            const std::size_t n = lb.count;
            const float* v = lb.values.get() + std::size_t(f - 1) * per * n;
            auto fill = [&](LeafSet<openvdb::FloatGrid>& set, const float* run) {
                FloatLeaf& leaf = set.make(b, origin);
                std::size_t i = 0;
                for (auto on = lb.kept.beginOn(); on; ++on) leaf.setValueOn(on.pos(), run[i++]);
            };
            fill(density, v);
            fill(halo, v + n);
            for (std::size_t k = 0; k < lines.size(); ++k) {
                fill(lines[k], v + (2 + k) * n);
                fill(halos[k], v + (2 + K + k) * n);
            }
        }
    });
}

template<typename Raw>
bool Compositor::keepSpotVoxel(const Raw& raw, float widthT, float roi, std::size_t b, const openvdb::Coord& origin,
                               openvdb::Index off)
{
    const int frames = mSettings.frames;
    auto frameVoxel = [&](int f) {
        if (frames == 1) return composeSpots(raw, widthT, roi);
        const FramePhase& ph = mPhases[std::size_t(f - 1)];
        return composeSpots([&](int c) { return loopFrameValue(mSettings, raw, c, f, ph); }, widthT, roi);
    };
    // Kept when any frame of the loop shows line or halo here, so every frame file has the same
    // topology.
    const SpotVoxel first = frameVoxel(1);
    bool shows = showsIn(first);
    for (int f = 2; f <= frames && !shows; ++f) shows = showsIn(frameVoxel(f));
    if (!shows || !mStill.density.enabled()) return shows; // a gather engine's loop keeps raw channels
    mStill.density.leaf(b, origin).setValueOn(off, first.density);
    mStill.halo.leaf(b, origin).setValueOn(off, first.halo);
    for (std::size_t k = 0; k < mStill.lines.size(); ++k) {
        mStill.lines[k].leaf(b, origin).setValueOn(off, first.lines[k]);
        mStill.halos[k].leaf(b, origin).setValueOn(off, first.halos[k]);
    }
    return true;
}

void Compositor::addStatic(std::size_t b, const openvdb::Coord& origin, openvdb::Index off, const openvdb::Coord& ijk,
                           const NoiseTexture* noise)
{
    auto& input = floats(OutputGrid::Input);
    auto& tangent = vectors(OutputGrid::Tangent);
    auto& velocity = vectors(OutputGrid::Velocity);
    const bool needWorld = tangent.enabled() || velocity.enabled() || bool(mInputs.color);
    const openvdb::Vec3d world = needWorld ? mDomain.worldOf(ijk) : openvdb::Vec3d(0.0);
    if (input.enabled()) {
        float v = 0.0f;
        if (noise) {
            v = noise->voxel(ijk);
        } else {
            // The narrowest line level's spot texture at the voxel centre.
            float s[2];
            mInputSpots->sample(ijk.asVec3d(), s);
            v = std::min(s[0], 1.0f);
        }
        input.leaf(b, origin).setValueOn(off, v);
    }
    if (tangent.enabled()) {
        // Unit flow direction at the voxel centre (zero at critical points), for illuminated lines
        // in renderers.
        openvdb::Vec3s t(0.0f);
        openvdb::Vec3d v;
        if (mField.sample(world, v)) {
            const double len = v.length();
            if (len > mField.maxSpeed() * 1e-6) t = openvdb::Vec3s(v / len);
        }
        tangent.leaf(b, origin).setValueOn(off, t);
    }
    if (velocity.enabled()) {
        // How the lines move here (world units per second): a loop's pattern along the unit flow
        // direction at its one speed, else the flow itself.
        openvdb::Vec3d v(0.0), out(0.0);
        if (mField.sample(world, v)) {
            const double len = v.length();
            if (mSettings.velocitySpeed > 0) {
                if (len > mField.maxSpeed() * 1e-6) out = v * (mSettings.velocitySpeed / len);
            } else {
                out = v * mSettings.velocityScale;
            }
        }
        velocity.leaf(b, origin).setValueOn(off, openvdb::Vec3s(out));
    }
    if (mInputs.color) {
        const double t = unitOf(mInputs.color.at(world), mSettings.colorRange);
        floats(OutputGrid::Scalar).leaf(b, origin).setValueOn(off, float(t));
        vectors(OutputGrid::Color).leaf(b, origin).setValueOn(off, openvdb::Vec3s(mInputs.colormap->linear(t)));
    }
}

void Compositor::finish()
{
    Moments all;
    for (const Moments& m : mMoments) all.merge(m); // brick order: the same sums for any thread count
    mMoments.clear();
    if (all.count > 0) mRaw = all.stats();
}

std::string Compositor::packMoments(const std::vector<std::size_t>& ids) const
{
    std::string out;
    for (std::size_t id : ids) {
        const std::uint64_t i = id;
        out.append(reinterpret_cast<const char*>(&i), sizeof i);
        out.append(reinterpret_cast<const char*>(&mMoments.at(id)), sizeof(Moments));
    }
    return out;
}

void Compositor::unpackMoments(const std::string& bytes)
{
    constexpr std::size_t kRecord = sizeof(std::uint64_t) + sizeof(Moments);
    if (bytes.size() % kRecord != 0) throw Error("malformed brick statistics message");
    for (std::size_t at = 0; at < bytes.size(); at += kRecord) {
        std::uint64_t id = 0;
        std::memcpy(&id, bytes.data() + at, sizeof id);
        if (id >= mMoments.size()) throw Error("brick statistics for brick " + std::to_string(id) + " out of range");
        std::memcpy(&mMoments[id], bytes.data() + at + sizeof id, sizeof(Moments));
    }
}

void Compositor::composeLeaves(int f, LeafSet<openvdb::FloatGrid>& density, LeafSet<openvdb::FloatGrid>& halo,
                               std::vector<LeafSet<openvdb::FloatGrid>>& lines,
                               std::vector<LeafSet<openvdb::FloatGrid>>& halos)
{
    const int frames = mSettings.frames;
    const bool spots = mSettings.spots, inPlace = !spots && f == frames && frames == 1;
    const FramePhase ph(f, frames);
    const ContrastStretch stretch(mRaw, ContrastStretch::kSigmas, mSettings.stretch);
    const ThreadLimit threadLimit(mSettings.threads);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mDomain.blockCount()), [&](const auto& range) {
        for (std::size_t b = range.begin(); b != range.end(); ++b) {
            const FloatLeaf* raw0 = mRawLeaves[0].at(b);
            if (!raw0) continue;
            const openvdb::Coord origin = raw0->origin();
            auto rawAt = [&](int c, openvdb::Index off) { return mRawLeaves[std::size_t(c)].at(b)->getValue(off); };
            auto value = [&](int c, openvdb::Index off) {
                return frames > 1 ? loopFrameValue(mSettings, [&](int k) { return rawAt(k, off); }, c, f, ph)
                                  : rawAt(c, off);
            };
            const FloatLeaf* roiLeaf = mRoiLeaves.enabled() ? mRoiLeaves.at(b) : nullptr;
            if (inPlace) {
                // A noise still: the raw leaf becomes the density leaf in place.
                for (auto it = mRawLeaves[0].at(b)->beginValueOn(); it; ++it) {
                    double v = stretch(*it);
                    if (roiLeaf) v *= roiLeaf->getValue(it.pos());
                    it.setValue(float(v));
                }
                continue;
            }
            FloatLeaf& d = density.make(b, origin);
            for (auto it = raw0->cbeginValueOn(); it; ++it) {
                const openvdb::Index off = it.pos();
                const float roi = roiLeaf ? roiLeaf->getValue(off) : 1.0f;
                if (!spots) {
                    d.setValueOn(off, float(stretch(value(0, off)) * roi));
                    continue;
                }
                const float widthT = mWidthLeaves.enabled() ? mWidthLeaves.at(b)->getValue(off) : 0.0f;
                const SpotVoxel sv = composeSpots([&](int c) { return value(c, off); }, widthT, roi);
                d.setValueOn(off, sv.density);
                halo.leaf(b, origin).setValueOn(off, sv.halo);
                for (int k = 0; k < int(lines.size()); ++k) {
                    lines[std::size_t(k)].leaf(b, origin).setValueOn(off, sv.lines[k]);
                    halos[std::size_t(k)].leaf(b, origin).setValueOn(off, sv.halos[k]);
                }
            }
        }
    });
}

openvdb::GridPtrVec Compositor::frame(int f)
{
    const int K = mSettings.levels, frames = mSettings.frames;
    const bool spots = mSettings.spots, last = f == frames;
    const std::size_t blocks = mDomain.blockCount();
    openvdb::GridPtrVec grids;
    auto addLevels = [&](std::vector<LeafSet<openvdb::FloatGrid>>& lines, std::vector<LeafSet<openvdb::FloatGrid>>& halos) {
        for (int k = 0; k < int(lines.size()); ++k) {
            grids.push_back(lines[std::size_t(k)].release(mDomain, outputGridName(OutputGrid::LevelLines, k + 1)));
            grids.push_back(halos[std::size_t(k)].release(mDomain, outputGridName(OutputGrid::LevelHalos, k + 1)));
        }
    };
    if (mSettings.composesOnArrival() && frames == 1) {
        grids.push_back(mStill.density.release(mDomain, outputGridName(OutputGrid::Density)));
        grids.push_back(mStill.halo.release(mDomain, outputGridName(OutputGrid::Halo)));
        addLevels(mStill.lines, mStill.halos);
        mStill = SpotFrame{};
    } else {
        // Compose this frame leaf by leaf from the kept channels (a comet loop: its kept values).
        LeafSet<openvdb::FloatGrid> density, halo;
        std::vector<LeafSet<openvdb::FloatGrid>> lines, halos;
        density.init(blocks);
        if (spots) {
            halo.init(blocks);
            if (mSettings.series()) {
                lines.resize(std::size_t(K));
                halos.resize(std::size_t(K));
                for (auto& s : lines) s.init(blocks);
                for (auto& s : halos) s.init(blocks);
            }
        }
        if (mSettings.composesOnArrival()) composeLoopLeaves(f, density, halo, lines, halos);
        else composeLeaves(f, density, halo, lines, halos);
        if (!spots && last && frames == 1) {
            grids.push_back(mRawLeaves[0].release(mDomain, outputGridName(OutputGrid::Density)));
        } else {
            grids.push_back(density.release(mDomain, outputGridName(OutputGrid::Density)));
            if (spots) {
                grids.push_back(halo.release(mDomain, outputGridName(OutputGrid::Halo)));
                addLevels(lines, halos);
            }
        }
        if (last) { // the kept channels are not needed any more
            mRawLeaves.clear();
            mWidthLeaves = {};
            mRoiLeaves = {};
            mLoopBlocks.clear();
        }
    }
    buildStatic();
    grids.insert(grids.end(), mStatic.begin(), mStatic.end());
    return grids;
}

void Compositor::buildStatic()
{
    if (mStaticBuilt) return;
    mStaticBuilt = true;
    forEachShared([&](const OutputGridRow& row, auto& set) {
        auto grid = set.release(mDomain, std::string(row.name));
        if constexpr (std::is_same_v<std::decay_t<decltype(set)>, LeafSet<openvdb::Vec3SGrid>>)
            grid->setVectorType(row.vecType);
        for (const auto& [key, value] : row.fixedMeta)
            grid->insertMeta(std::string(key), openvdb::StringMetadata(std::string(value)));
        if (row.id == OutputGrid::Velocity && mSettings.velocitySpeed > 0)
            grid->insertMeta("licvdb_loop_speed", openvdb::DoubleMetadata(mSettings.velocitySpeed));
        mStatic.push_back(grid);
    });
}

} // namespace lic

#include "lic/texture/Advection.h"

#include "lic/util/Error.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_map>

namespace lic {

namespace {

/// The hash seed of a generation: generation 0 is the bake's own seed (frame one = a still bake).
std::uint64_t generationSeed(std::uint64_t seed, std::uint32_t gen)
{
    return gen == 0 ? seed : hashCoord(seed, int(gen), 0x5EED, 0x71E);
}

/// Back-trace of an output voxel's centre over dt (midpoint rule), in output index space; false
/// where the velocity cannot be sampled (outside the field).
bool traceBack(const OutputDomain& domain, const VelocityField& field, const openvdb::Coord& ijk, double dt,
               openvdb::Vec3d& p)
{
    const openvdb::Vec3d x = domain.worldOf(ijk);
    openvdb::Vec3d v;
    if (!field.sample(x, v)) return false;
    openvdb::Vec3d vm;
    if (!field.sample(x - 0.5 * dt * v, vm)) vm = v;
    p = domain.map().toIndex(x - dt * vm);
    return true;
}

/// Forward move of a position over dt (midpoint rule), output index space; false if it left.
bool traceForward(const OutputDomain& domain, const VelocityField& field, openvdb::Vec3d& c, double dt)
{
    const openvdb::Vec3d x = domain.map().toWorld(c);
    openvdb::Vec3d v;
    if (!field.sample(x, v)) return false;
    openvdb::Vec3d vm;
    if (!field.sample(x + 0.5 * dt * v, vm)) vm = v;
    c = domain.map().toIndex(x + dt * vm);
    return true;
}

/// A uniform hash grid of points (cells of `cell` voxels) for "is any point within r".
class PointGrid
{
public:
    explicit PointGrid(double cell) : mCell(cell) {}
    void insert(const openvdb::Vec3d& p) { mCells[key(p)].push_back(p); }
    bool anyWithin(const openvdb::Vec3d& p, double r) const
    {
        const openvdb::Coord c = cellOf(p);
        const int reach = int(std::ceil(r / mCell));
        for (int i = -reach; i <= reach; ++i)
            for (int j = -reach; j <= reach; ++j)
                for (int k = -reach; k <= reach; ++k) {
                    const auto it = mCells.find(key(c + openvdb::Coord(i, j, k)));
                    if (it == mCells.end()) continue;
                    for (const auto& q : it->second)
                        if ((q - p).lengthSqr() < r * r) return true;
                }
        return false;
    }

private:
    openvdb::Coord cellOf(const openvdb::Vec3d& p) const
    {
        return openvdb::Coord(int(std::floor(p[0] / mCell)), int(std::floor(p[1] / mCell)), int(std::floor(p[2] / mCell)));
    }
    static std::uint64_t key(const openvdb::Coord& c)
    {
        return (std::uint64_t(std::uint32_t(c[0]) & 0x1FFFFF) << 42) | (std::uint64_t(std::uint32_t(c[1]) & 0x1FFFFF) << 21) |
               std::uint64_t(std::uint32_t(c[2]) & 0x1FFFFF);
    }
    std::uint64_t key(const openvdb::Vec3d& p) const { return key(cellOf(p)); }
    double mCell;
    std::unordered_map<std::uint64_t, std::vector<openvdb::Vec3d>> mCells;
};

} // namespace

// ---- AdvectedNoise -----------------------------------------------------------------------------

namespace {

std::vector<std::uint32_t> allBlocks(const OutputDomain& domain)
{
    std::vector<std::uint32_t> all(domain.blockCount());
    for (std::size_t b = 0; b < all.size(); ++b) all[b] = std::uint32_t(b);
    return all;
}

/// The blocks of `domain` with a voxel within `reach` voxels (per axis) of the blocks `blocks` of
/// `from` (a domain on the same lattice), ascending.
std::vector<std::uint32_t> blocksNear(const OutputDomain& domain, const OutputDomain& from,
                                      const std::vector<std::uint32_t>& blocks, int reach)
{
    std::vector<std::uint8_t> mark(domain.blockCount(), 0);
    for (std::uint32_t b : blocks) {
        const openvdb::Coord o = from.blockOrigin(b);
        domain.markBlocks(openvdb::CoordBBox(o - openvdb::Coord(reach), o + openvdb::Coord(OutputDomain::kBlockDim - 1 + reach)),
                          mark);
    }
    return OutputDomain::markedBlocks(mark);
}

std::string voxelName(const openvdb::Coord& c)
{
    return "(" + std::to_string(c[0]) + ", " + std::to_string(c[1]) + ", " + std::to_string(c[2]) + ")";
}

template<typename T>
void put(std::string& out, const T* v, std::size_t n)
{
    out.append(reinterpret_cast<const char*>(v), n * sizeof(T));
}

template<typename T>
void take(const std::string& in, std::size_t& at, T* v, std::size_t n)
{
    if (at + n * sizeof(T) > in.size()) throw Error("carried noise: truncated block message");
    std::memcpy(v, in.data() + at, n * sizeof(T));
    at += n * sizeof(T);
}

} // namespace

std::vector<std::uint32_t> AdvectedNoise::sourceBlocks(const OutputDomain& prev, const OutputDomain& next,
                                                       const std::vector<std::uint32_t>& keep, double displacement)
{
    // advance() computes the kept blocks and their neighbours (the refresh test looks one voxel
    // on), each voxel reading the previous frame at the voxel nearest its back-traced position.
    const std::vector<std::uint32_t> computed = blocksNear(next, next, keep, 1);
    const int reach = int(std::ceil(std::max(0.0, displacement) + 0.5)) + 1;
    return blocksNear(prev, next, computed, reach);
}

void AdvectedNoise::hold(const OutputDomain& domain, const std::vector<std::uint32_t>& blocks)
{
    mDomain = std::make_unique<OutputDomain>(domain);
    mLocal.assign(domain.blockCount(), -1);
    mHeld = blocks;
    for (std::size_t i = 0; i < blocks.size(); ++i) mLocal[blocks[i]] = std::int32_t(i);
}

void AdvectedNoise::start(const OutputDomain& domain, const Part* part)
{
    constexpr int V = OutputDomain::kBlockVoxels;
    hold(domain, part ? part->keep : allBlocks(domain));
    mX.assign(mHeld.size() * V, openvdb::Vec3f(0.0f));
    mGen.assign(mHeld.size() * V, 0);
    mGeneration = 0;
    tbb::parallel_for(std::size_t(0), mHeld.size(), [&](std::size_t i) {
        const std::size_t b = mHeld[i];
        for (int off = 0; off < V; ++off)
            if (domain.blockMask(b).isOn(openvdb::Index(off)))
                mX[i * V + std::size_t(off)] = domain.coordOf(b * V + std::size_t(off)).asVec3s();
    });
    mStats = {};
    if (!part) {
        mStats.voxels = domain.activeVoxelCount();
    } else {
        for (std::uint32_t b : part->own) mStats.voxels += domain.blockMask(b).countOn();
    }
}

void AdvectedNoise::advance(const OutputDomain& domain, const VelocityField& field, double dt, const Part* part)
{
    constexpr int V = OutputDomain::kBlockVoxels;
    if (!mDomain) throw Error("AdvectedNoise::advance before start");
    const OutputDomain& prev = *mDomain;
    const std::uint32_t gen = ++mGeneration;
    // Pass 1 over the kept blocks and their neighbours (one process: every block): carry or enter.
    const std::vector<std::uint32_t> keep = part ? part->keep : allBlocks(domain);
    const std::vector<std::uint32_t> near = part ? blocksNear(domain, domain, keep, 1) : keep;
    std::vector<std::int32_t> nearLocal(domain.blockCount(), -1);
    for (std::size_t i = 0; i < near.size(); ++i) nearLocal[near[i]] = std::int32_t(i);
    const std::size_t S = near.size() * V;
    std::vector<openvdb::Vec3f> X(S, openvdb::Vec3f(0.0f));
    std::vector<std::uint32_t> G(S, 0);
    std::vector<std::uint8_t> how(S, 0); // 1 carried, 2 entered
    tbb::parallel_for(std::size_t(0), near.size(), [&](std::size_t i) {
        const std::size_t b = near[i];
        for (int off = 0; off < V; ++off) {
            if (!domain.blockMask(b).isOn(openvdb::Index(off))) continue;
            const std::size_t s = i * V + std::size_t(off);
            const openvdb::Coord ijk = domain.coordOf(b * V + std::size_t(off));
            openvdb::Vec3d p;
            if (traceBack(domain, field, ijk, dt, p)) {
                const openvdb::Coord q = OutputDomain::nearestVoxel(p);
                const std::int64_t ps = prev.slotOf(q);
                if (ps >= 0) {
                    const std::uint32_t pb = std::uint32_t(ps / V);
                    if (mLocal[pb] < 0) {
                        throw Error("internal error: carried noise: voxel " + voxelName(ijk) + " reaches back to " +
                                    voxelName(q) + ", whose block this process does not hold");
                    }
                    const std::size_t ls = base(pb) + std::size_t(ps % V);
                    X[s] = mX[ls] + openvdb::Vec3f(p - q.asVec3d());
                    G[s] = mGen[ls];
                    how[s] = 1;
                    continue;
                }
            }
            X[s] = ijk.asVec3s();
            G[s] = gen;
            how[s] = 2;
        }
    });
    // Pass 2 over the kept blocks: refresh where the carried coordinates no longer step by about
    // one voxel per voxel (read-only: a neighbour's test sees the unrefreshed state).
    auto nearSlot = [&](std::int64_t slot) {
        const std::int32_t l = nearLocal[std::size_t(slot / V)];
        if (l < 0) throw Error("internal error: carried noise: a neighbour's block was not computed");
        return std::size_t(l) * V + std::size_t(slot % V);
    };
    std::vector<std::uint8_t> state(keep.size() * V, 0); // how, or 3: refreshed
    tbb::parallel_for(std::size_t(0), keep.size(), [&](std::size_t i) {
        const std::size_t b = keep[i];
        for (int off = 0; off < V; ++off) {
            if (!domain.blockMask(b).isOn(openvdb::Index(off))) continue;
            const std::size_t s = nearSlot(std::int64_t(b * V) + off);
            const openvdb::Coord ijk = domain.coordOf(b * V + std::size_t(off));
            bool refresh = false;
            for (int a = 0; a < 3 && how[s] == 1 && !refresh; ++a) {
                openvdb::Coord n = ijk;
                n[a] += 1;
                const std::int64_t ns = domain.slotOf(n);
                if (ns < 0) continue;
                const std::size_t t = nearSlot(ns);
                if (G[t] != G[s]) continue;
                const float d = (X[t] - X[s]).length();
                refresh = d < 0.5f || d > 2.0f;
            }
            state[i * V + std::size_t(off)] = refresh ? 3 : how[s];
        }
    });
    // Pass 3: the kept blocks' state. In place where every computed block is kept (one process:
    // no second copy of the arrays); a part copies its kept blocks out of the computed ones.
    const bool inPlace = near.size() == keep.size(); // near ⊇ keep
    std::vector<openvdb::Vec3f> KX;
    std::vector<std::uint32_t> KG;
    if (!inPlace) KX.assign(keep.size() * V, openvdb::Vec3f(0.0f)), KG.assign(keep.size() * V, 0);
    tbb::parallel_for(std::size_t(0), keep.size(), [&](std::size_t i) {
        const std::size_t b = keep[i];
        for (int off = 0; off < V; ++off) {
            const std::size_t k = i * V + std::size_t(off), s = inPlace ? k : nearSlot(std::int64_t(b * V) + off);
            const bool refresh = state[k] == 3;
            openvdb::Vec3f& x = inPlace ? X[s] : KX[k];
            std::uint32_t& g = inPlace ? G[s] : KG[k];
            x = refresh ? domain.coordOf(b * V + std::size_t(off)).asVec3s() : X[s];
            g = refresh ? gen : G[s];
        }
    });
    hold(domain, keep);
    mX.swap(inPlace ? X : KX);
    mGen.swap(inPlace ? G : KG);
    Stats st;
    auto count = [&](std::uint32_t b) {
        const std::size_t i = std::size_t(mLocal[b]);
        for (int off = 0; off < V; ++off) {
            const std::uint8_t h = state[i * V + std::size_t(off)];
            st.carried += h == 1, st.entered += h == 2, st.refreshed += h == 3;
        }
    };
    if (part) {
        for (std::uint32_t b : part->own) {
            st.voxels += domain.blockMask(b).countOn();
            count(b);
        }
    } else {
        st.voxels = domain.activeVoxelCount();
        for (std::uint32_t b : keep) count(b);
    }
    mStats = st;
}

float AdvectedNoise::raw(const openvdb::Coord& ijk) const
{
    constexpr int V = OutputDomain::kBlockVoxels;
    const std::int64_t s = mDomain ? mDomain->slotOf(ijk) : -1;
    if (s < 0) return whiteNoise(mSeed, ijk[0], ijk[1], ijk[2]);
    const std::size_t b = std::size_t(s / V);
    if (mLocal[b] < 0)
        throw Error("internal error: carried noise of voxel " + voxelName(ijk) + " is not held by this process");
    const std::size_t ls = base(std::uint32_t(b)) + std::size_t(s % V);
    const openvdb::Coord q = OutputDomain::nearestVoxel(mX[ls]);
    return whiteNoise(generationSeed(mSeed, mGen[ls]), q[0], q[1], q[2]);
}

std::string AdvectedNoise::pack(const std::vector<std::uint32_t>& blocks) const
{
    constexpr int V = OutputDomain::kBlockVoxels;
    std::string out;
    out.reserve(blocks.size() * (12 + V * 16));
    for (std::uint32_t b : blocks) {
        if (!holds(b)) throw Error("internal error: carried noise: packing a block this process does not hold");
        const openvdb::Coord o = mDomain->blockOrigin(b);
        const std::int32_t origin[3] = {o[0], o[1], o[2]};
        put(out, origin, 3);
        put(out, &mX[base(b)], V);
        put(out, &mGen[base(b)], V);
    }
    return out;
}

void AdvectedNoise::unpack(const std::string& bytes)
{
    constexpr int V = OutputDomain::kBlockVoxels;
    if (!mDomain) throw Error("AdvectedNoise::unpack before start");
    std::size_t at = 0;
    while (at < bytes.size()) {
        std::int32_t origin[3];
        take(bytes, at, origin, 3);
        const openvdb::Coord o(origin[0], origin[1], origin[2]);
        const std::int64_t b = mDomain->blockOf(o);
        if (b < 0 || mDomain->blockOrigin(std::size_t(b)) != o)
            throw Error("carried noise: a block message names block " + voxelName(o) + ", which the frame does not have");
        if (holds(std::uint32_t(b))) {
            at += V * (sizeof(openvdb::Vec3f) + sizeof(std::uint32_t));
            if (at > bytes.size()) throw Error("carried noise: truncated block message");
            continue;
        }
        mLocal[std::size_t(b)] = std::int32_t(mHeld.size());
        mHeld.push_back(std::uint32_t(b));
        mX.resize(mX.size() + V);
        mGen.resize(mGen.size() + V);
        take(bytes, at, &mX[mX.size() - V], V);
        take(bytes, at, &mGen[mGen.size() - V], V);
    }
}

// ---- SpotFlock ---------------------------------------------------------------------------------

namespace {

/// A frame's birth candidates: the placement at half the spacing (this frame's seed) inside the
/// active voxels, in a hashed order (so births up to a budget spread over all the room there is).
std::vector<openvdb::Vec3d> birthCandidates(const OutputDomain& domain, SpotPlacement p, int frame)
{
    const openvdb::CoordBBox ib = domain.indexBBox();
    const openvdb::BBoxd box(ib.min().asVec3d() - openvdb::Vec3d(0.5), ib.max().asVec3d() + openvdb::Vec3d(0.5));
    const std::uint64_t seed = hashCoord(p.seed, frame, 0x59A7, 0x0F10C);
    p.seed = seed;
    p.spacing *= 0.5; // dense candidates, so a gap is found wherever it opens
    std::vector<std::pair<std::uint64_t, openvdb::Vec3d>> keyed;
    int i = 0;
    for (const openvdb::Vec3d& c : placeSpots(p, box)) {
        ++i;
        if (domain.slotOf(OutputDomain::nearestVoxel(c)) >= 0) keyed.emplace_back(hashCoord(seed, i, 0xB1A7, 0x0DE5), c);
    }
    std::sort(keyed.begin(), keyed.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<openvdb::Vec3d> out;
    out.reserve(keyed.size());
    for (const auto& k : keyed) out.push_back(k.second);
    return out;
}

/// Whether a point at c would have come in from outside the active voxels within the last
/// `frames` frames (traced back over dt each, in this frame's flow).
bool cameInWithin(const OutputDomain& domain, const VelocityField& field, openvdb::Vec3d c, double dt, int frames)
{
    for (int k = 0; k < frames; ++k)
        if (!traceForward(domain, field, c, -dt) || domain.slotOf(OutputDomain::nearestVoxel(c)) < 0) return true;
    return false;
}

} // namespace

void SpotFlock::start(const SpotSet& spots, const OutputDomain& domain)
{
    mSpots.clear();
    mNextId = 0;
    for (std::size_t i = 0; i < spots.centers.size(); ++i) {
        Spot s;
        s.c = spots.centers[i];
        s.id = mNextId++;
        s.age = mParams.fadeFrames; // frame one is drawn at full weight
        s.roi = i < spots.weights.size() ? spots.weights[i] : 1.0f;
        mSpots.push_back(s);
    }
    mPerVoxel = double(mSpots.size()) / double(std::max<std::uint64_t>(1, domain.activeVoxelCount()));
    mStats = {};
    mStats.alive = mSpots.size();
}

float SpotFlock::weightOf(const Spot& s) const
{
    const float F = float(std::max(1, mParams.fadeFrames));
    float w = std::min(1.0f, float(s.age + 1) / F);
    if (s.dying >= 0) w = std::min(w, std::max(0.0f, 1.0f - float(s.dying + 1) / F));
    return w * s.roi;
}

void SpotFlock::advance(const OutputDomain& domain, const VelocityField& field, double dt, int frame,
                        const Accept& accept)
{
    Stats st;
    // 1. Move (independent per spot), then drop those that left the active voxels.
    std::vector<std::uint8_t> gone(mSpots.size(), 0);
    tbb::parallel_for(std::size_t(0), mSpots.size(), [&](std::size_t i) {
        Spot& s = mSpots[i];
        if (!traceForward(domain, field, s.c, dt) || domain.slotOf(OutputDomain::nearestVoxel(s.c)) < 0) gone[i] = 1;
    });
    std::vector<Spot> kept;
    kept.reserve(mSpots.size());
    for (std::size_t i = 0; i < mSpots.size(); ++i) {
        if (gone[i]) {
            ++st.left;
            continue;
        }
        Spot s = mSpots[i];
        ++s.age;
        if (s.dying >= 0) ++s.dying;
        if (s.dying + 1 >= mParams.fadeFrames) continue; // faded out
        s.roi = accept ? accept(s.c) : 1.0f;
        if (s.roi <= 0.0f) continue;
        kept.push_back(s);
    }
    // 2. Retire crowded spots: older spots (lower id) win; a retiring spot does not crowd others.
    const double d = mParams.placement.spacing;
    const double rRetire = 0.5 * kPoissonRadius * d, rNew = kPoissonRadius * d;
    std::sort(kept.begin(), kept.end(), [](const Spot& a, const Spot& b) { return a.id < b.id; });
    PointGrid alive(rNew);
    for (Spot& s : kept) {
        if (s.dying < 0 && alive.anyWithin(s.c, rRetire)) s.dying = 0;
        if (s.dying < 0) alive.insert(s.c);
        else ++st.retiring;
    }
    // 3. New spots where the flow opened space, as many as keep frame one's number per active
    //    voxel: this frame's candidates, at the placement distance from every living spot and
    //    from each other. One that would have come in from outside within the fade time starts
    //    at full weight (it stands for a spot that came in whole); one born deeper fades in.
    const std::size_t target = std::size_t(std::llround(mPerVoxel * double(domain.activeVoxelCount())));
    std::size_t living = 0;
    for (const Spot& s : kept) living += s.dying < 0;
    for (const openvdb::Vec3d& c : birthCandidates(domain, mParams.placement, frame)) {
        if (living >= target) break;
        if (alive.anyWithin(c, rNew)) continue;
        const float w = accept ? accept(c) : 1.0f;
        if (w <= 0.0f) continue;
        Spot s;
        s.c = c;
        s.id = mNextId++;
        s.age = cameInWithin(domain, field, c, dt, mParams.fadeFrames) ? mParams.fadeFrames : 0;
        s.roi = w;
        kept.push_back(s);
        alive.insert(c);
        ++living;
        ++st.born;
    }
    mSpots.swap(kept);
    st.alive = mSpots.size();
    mStats = st;
}

SpotSet SpotFlock::current() const
{
    SpotSet set;
    set.centers.reserve(mSpots.size());
    set.weights.reserve(mSpots.size());
    for (const Spot& s : mSpots) {
        const float w = weightOf(s);
        if (w <= 0.0f) continue;
        set.centers.push_back(s.c);
        set.weights.push_back(w);
    }
    return set;
}

} // namespace lic

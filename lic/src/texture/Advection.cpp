#include "lic/texture/Advection.h"

#include "lic/util/Error.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
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

void AdvectedNoise::start(const OutputDomain& domain)
{
    mDomain = std::make_unique<OutputDomain>(domain);
    mGeneration = 0;
    mX.assign(domain.slotCount(), openvdb::Vec3f(0.0f));
    mGen.assign(domain.slotCount(), 0);
    tbb::parallel_for(std::size_t(0), domain.slotCount(), [&](std::size_t s) {
        if (domain.isActive(s)) mX[s] = domain.coordOf(s).asVec3s();
    });
    mStats = {};
    mStats.voxels = domain.activeVoxelCount();
}

void AdvectedNoise::advance(const OutputDomain& domain, const VelocityField& field, double dt)
{
    if (!mDomain) throw Error("AdvectedNoise::advance before start");
    const OutputDomain& prev = *mDomain;
    const std::uint32_t gen = ++mGeneration;
    const std::size_t S = domain.slotCount();
    std::vector<openvdb::Vec3f> X(S, openvdb::Vec3f(0.0f));
    std::vector<std::uint32_t> G(S, 0);
    std::vector<std::uint8_t> how(S, 0); // 1 carried, 2 entered
    tbb::parallel_for(std::size_t(0), S, [&](std::size_t s) {
        if (!domain.isActive(s)) return;
        const openvdb::Coord ijk = domain.coordOf(s);
        openvdb::Vec3d p;
        if (traceBack(domain, field, ijk, dt, p)) {
            const openvdb::Coord q = OutputDomain::nearestVoxel(p);
            const std::int64_t ps = prev.slotOf(q);
            if (ps >= 0) {
                X[s] = mX[std::size_t(ps)] + openvdb::Vec3f(p - q.asVec3d());
                G[s] = mGen[std::size_t(ps)];
                how[s] = 1;
                return;
            }
        }
        X[s] = ijk.asVec3s();
        G[s] = gen;
        how[s] = 2;
    });
    // Refresh where the carried coordinates no longer step by about one voxel per voxel.
    std::vector<std::uint8_t> refresh(S, 0);
    tbb::parallel_for(std::size_t(0), S, [&](std::size_t s) {
        if (how[s] != 1) return;
        const openvdb::Coord ijk = domain.coordOf(s);
        for (int a = 0; a < 3; ++a) {
            openvdb::Coord n = ijk;
            n[a] += 1;
            const std::int64_t ns = domain.slotOf(n);
            if (ns < 0 || G[std::size_t(ns)] != G[s]) continue;
            const float d = (X[std::size_t(ns)] - X[s]).length();
            if (d < 0.5f || d > 2.0f) {
                refresh[s] = 1;
                return;
            }
        }
    });
    Stats st;
    st.voxels = domain.activeVoxelCount();
    for (std::size_t s = 0; s < S; ++s) {
        if (refresh[s]) {
            X[s] = domain.coordOf(s).asVec3s();
            G[s] = gen;
            ++st.refreshed;
        } else if (how[s] == 1) {
            ++st.carried;
        } else if (how[s] == 2) {
            ++st.entered;
        }
    }
    mX.swap(X);
    mGen.swap(G);
    mDomain = std::make_unique<OutputDomain>(domain);
    mStats = st;
}

float AdvectedNoise::raw(const openvdb::Coord& ijk) const
{
    const std::int64_t s = mDomain ? mDomain->slotOf(ijk) : -1;
    if (s < 0) return whiteNoise(mSeed, ijk[0], ijk[1], ijk[2]);
    const openvdb::Coord q = OutputDomain::nearestVoxel(mX[std::size_t(s)]);
    return whiteNoise(generationSeed(mSeed, mGen[std::size_t(s)]), q[0], q[1], q[2]);
}

// ---- SpotFlock ---------------------------------------------------------------------------------

void SpotFlock::start(const SpotSet& spots)
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
    PointGrid living(rNew);
    for (Spot& s : kept) {
        if (s.dying < 0 && living.anyWithin(s.c, rRetire)) s.dying = 0;
        if (s.dying < 0) living.insert(s.c);
        else ++st.retiring;
    }
    // 3. New spots where the flow opened space: this frame's candidates, at the placement
    //    distance from every living spot and from each other.
    const openvdb::CoordBBox ib = domain.indexBBox();
    const openvdb::BBoxd box(ib.min().asVec3d() - openvdb::Vec3d(0.5), ib.max().asVec3d() + openvdb::Vec3d(0.5));
    SpotPlacement p = mParams.placement;
    p.seed = hashCoord(mParams.placement.seed, frame, 0x59A7, 0x0F10C);
    p.spacing = 0.5 * d; // dense candidates, so a gap is filled wherever it opens
    for (const openvdb::Vec3d& c : placeSpots(p, box)) {
        if (domain.slotOf(OutputDomain::nearestVoxel(c)) < 0) continue;
        if (living.anyWithin(c, rNew)) continue;
        const float w = accept ? accept(c) : 1.0f;
        if (w <= 0.0f) continue;
        Spot s;
        s.c = c;
        s.id = mNextId++;
        s.age = 0;
        s.roi = w;
        kept.push_back(s);
        living.insert(c);
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

// Temporally coherent input textures for unsteady flow: the texture is carried by the flow from
// frame to frame, and each frame is convolved along that frame's own flow (docs/technique.md §11).
//
// Noise: Lagrangian–Eulerian advection (Jobard, Erlebacher & Hussaini 2002). Every output voxel
// carries a texture coordinate X (output index space) and a generation g; a frame's white noise
// at voxel x is whiteNoise(seed of g, round(X(x))). Advancing one frame traces x back over the
// frame interval (midpoint rule) to p, takes the coordinate of the voxel q nearest p and adds the
// sub-voxel rest: X'(x) = X(q) + (p − q), g'(x) = g(q). Flow that enters from outside, or voxels
// that were not active, start afresh (X = x, a new generation); so do voxels where the carried
// coordinates have been stretched or compressed (a neighbour's X is not between ½ and 2 voxels
// away) — that is where nearest-voxel copying would otherwise repeat or skip noise values.
//
// Spots: particles. They move with the flow (midpoint rule), leave when they leave the active
// domain, fade out over a few frames when another spot comes closer than half the placement
// distance (older spots win), and new ones are born where the flow opens space (candidates from
// the recipe's distribution at half the spacing, a new seed per frame, taken in a hashed order,
// kept at the placement distance from every spot). Births replace what left or retired one for
// one: the number of living spots stays frame one's number per active voxel, whatever the speed
// (filling every gap as it opened packed incoming spots closer than frame one's Poisson
// placement: +6 to +15 % over 40 frames, more the slower the flow). A spot born where the flow
// just entered (its position one frame back is outside the active voxels) comes in at full
// weight, as the ones that leave go at once; one born inside fades in. So the density of lines and
// the brightness stay steady and nothing pops inside the domain.
//
// Everything is deterministic: per-voxel work reads only the previous frame's state, and spots
// are handled in one fixed order.
#pragma once

#include "lic/field/Field.h"
#include "lic/texture/Noise.h"
#include "lic/field/OutputDomain.h"
#include "lic/texture/Spots.h"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace lic {

/// Carried noise (see the file comment). Positions are output index space of domains that share
/// one index lattice (fields of one sequence have one transform).
///
/// A distributed sequence holds a part: each process keeps the state of the blocks its bricks and
/// their margins read (`Part::keep`), and before advancing imports, from the processes that own
/// them, the previous frame's blocks it reaches back to (sourceBlocks(): the kept blocks grown by
/// one block and by the frame's displacement). Every voxel's state is computed from the same
/// inputs by the same arithmetic wherever it is computed, so a part equals the whole on its blocks.
class AdvectedNoise
{
public:
    /// Blocks (indices into a domain) to compute and keep: null = every block of the domain.
    struct Part
    {
        std::vector<std::uint32_t> keep; ///< ascending: blocks whose state this process keeps
        std::vector<std::uint32_t> own;  ///< ascending, within keep: blocks counted in stats()
    };

    explicit AdvectedNoise(std::uint64_t seed) : mSeed(seed) {}

    /// Frame one: X = x and generation 0, so its noise is the still bake's (whiteNoise(seed, x)).
    void start(const OutputDomain& domain, const Part* part = nullptr);
    /// The next frame: `domain` and `field` are the new frame's, `dt` the time between the frames
    /// in the field's time unit (velocity × dt = world displacement). Parallel over voxels, the
    /// same result for any thread count. With a part, the previous frame's blocks within
    /// sourceBlocks() of it must be held (import them with unpack() first).
    /// @throw lic::Error when a voxel reaches back to a block that is not held.
    void advance(const OutputDomain& domain, const VelocityField& field, double dt, const Part* part = nullptr);

    /// White noise in [0, 1) at an output voxel of the current frame (outside its active voxels:
    /// the still noise of the seed). Thread-safe.
    /// @throw lic::Error for an active voxel of a block this part does not hold.
    float raw(const openvdb::Coord& ijk) const;
    /// raw() as NoiseTexture's RawNoise; the texture must not outlive this object's frame.
    NoiseTexture::RawNoise rawNoise() const
    {
        return [this](const openvdb::Coord& ijk) { return raw(ijk); };
    }

    /// The blocks of `prev` that advance() to `next` reads for the blocks `keep` of `next`: those
    /// within one block plus `displacement` output voxels (the frame's largest move, ≥ 0) of them.
    static std::vector<std::uint32_t> sourceBlocks(const OutputDomain& prev, const OutputDomain& next,
                                                   const std::vector<std::uint32_t>& keep, double displacement);
    /// The current frame's domain (null before start()).
    const OutputDomain* domain() const { return mDomain.get(); }
    /// Whether the state of block `b` of the current domain is held here.
    bool holds(std::uint32_t b) const { return b < mLocal.size() && mLocal[b] >= 0; }
    /// The state of held blocks (ascending ids), as bytes for another process's unpack().
    std::string pack(const std::vector<std::uint32_t>& blocks) const;
    /// Hold the blocks another process packed (of the same current domain). Blocks held already
    /// are left as they are (their state is the same wherever it was computed).
    /// @throw lic::Error for a malformed message or a block the domain does not have.
    void unpack(const std::string& bytes);

    /// Counters of the last advance() (over the part's own blocks).
    struct Stats
    {
        std::uint64_t voxels = 0;    ///< active voxels of the frame
        std::uint64_t carried = 0;   ///< took their noise from the previous frame
        std::uint64_t entered = 0;   ///< came from outside the previous frame's active voxels
        std::uint64_t refreshed = 0; ///< started afresh where the texture was stretched or squeezed
    };
    const Stats& stats() const { return mStats; }
    std::uint32_t generation() const { return mGeneration; }

private:
    /// Local storage index of held block b's first voxel.
    std::size_t base(std::uint32_t b) const { return std::size_t(mLocal[b]) * OutputDomain::kBlockVoxels; }
    /// Make `domain` current and index `blocks` (storage is the caller's to fill).
    void hold(const OutputDomain& domain, const std::vector<std::uint32_t>& blocks);

    std::uint64_t mSeed;
    std::uint32_t mGeneration = 0;
    std::unique_ptr<OutputDomain> mDomain; ///< the current frame's (its blocks index mLocal)
    std::vector<std::int32_t> mLocal;      ///< per block of mDomain: its place in the arrays, or −1
    std::vector<std::uint32_t> mHeld;      ///< held blocks, in storage order
    std::vector<openvdb::Vec3f> mX;        ///< per held voxel: carried texture coordinate
    std::vector<std::uint32_t> mGen;       ///< per held voxel: generation
    Stats mStats;
};

/// Carried spots (see the file comment).
class SpotFlock
{
public:
    struct Params
    {
        SpotPlacement placement;     ///< distribution, spacing, jitter and seed of frame one
        int fadeFrames = 4;          ///< frames over which spots fade in and out (≥ 1)
    };
    /// Weight of a spot at an output-index position (a region of interest; 1 = everywhere).
    using Accept = std::function<float(const openvdb::Vec3d&)>;

    explicit SpotFlock(const Params& params) : mParams(params) {}

    /// Frame one: these spots (a still bake's), at full weight, over `domain`'s active voxels
    /// (their number per active voxel is what later frames keep).
    void start(const SpotSet& spots, const OutputDomain& domain);
    /// The next frame: move every spot over `dt` along `field`, drop those that left `domain`'s
    /// active voxels, retire crowded ones, add new ones where there is room. `frame` (2, 3, …)
    /// seeds the new spots' placement.
    void advance(const OutputDomain& domain, const VelocityField& field, double dt, int frame,
                 const Accept& accept = {});
    /// The spots of the current frame with their weights (fade × region weight).
    SpotSet current() const;

    struct Stats
    {
        std::size_t alive = 0;    ///< spots drawn this frame (fading ones included)
        std::size_t born = 0;     ///< added this frame
        std::size_t left = 0;     ///< left the domain this frame
        std::size_t retiring = 0; ///< fading out (crowded)
    };
    const Stats& stats() const { return mStats; }

private:
    struct Spot
    {
        openvdb::Vec3d c;       ///< output index position
        std::uint64_t id = 0;   ///< birth order: lower = older
        int age = 0;            ///< frames since birth
        int dying = -1;         ///< frames since retirement began (−1: alive)
        float roi = 1.0f;       ///< region weight at the current position
    };
    float weightOf(const Spot& s) const;

    Params mParams;
    double mPerVoxel = 0.0; ///< living spots per active voxel (frame one's)
    std::vector<Spot> mSpots;
    std::uint64_t mNextId = 0;
    Stats mStats;
};

} // namespace lic

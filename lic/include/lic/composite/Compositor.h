// Compositing: a convolution's raw channels become the output grids. Each finished brick's
// channels become VDB leaf nodes right away (lines and halos normalised, width blended,
// region-of-interest post-mask, colour, tangent, input; voxels whose line and halo are both ~0 left
// inactive), and the brick's buffers go back to its worker. What needs the whole volume is gathered
// cheaply: the noise contrast from per-brick moments merged in brick order, and a loop's frames
// composed leaf by leaf from the ripple sums kept per voxel. Memory: the output grids themselves,
// never a dense array over the volume.
#pragma once

#include "lic/composite/Animation.h"
#include "lic/composite/Colormap.h"
#include "lic/composite/Contrast.h"
#include "lic/composite/LeafSet.h"
#include "lic/composite/OutputGrids.h"
#include "lic/engine/Driver.h"
#include "lic/field/Bricks.h"
#include "lic/field/Field.h"
#include "lic/field/OutputDomain.h"
#include "lic/field/ScalarField.h"
#include "lic/texture/Noise.h"
#include "lic/texture/Spots.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace lic {

/// Voxels of a spot bake whose line and halo are both at most this stay inactive (1% of a line
/// core: invisible in any renderer, and well below the raycaster's halo threshold of 0.05).
constexpr float kSparseEpsilon = 0.01f;

/// What to composite. Ranges are in the scalars' own units.
struct CompositeSettings
{
    int frames = 1;        ///< cyclic loop frames (1 = a still): the raw channels are ripple sums when > 1
    /// A comet loop (spots, splat engine): the raw channels are every frame's, frame-major
    /// (LicSettings::comets), instead of ripple sums.
    bool comets = false;
    bool spots = false;    ///< spot input (lines and halos per width level), else noise
    int levels = 1;        ///< spot width levels K: texture channels 2K (lines, then halos)
    /// Spots: per level, the peak a single spot gives on a straight line (lines and halos): what
    /// maps a line's core to 1 (engine/Kernels.h spotPeak(); 1 without normalisation).
    std::vector<double> linePeak{1.0}, haloPeak{1.0};
    bool stretch = true;   ///< noise: contrast stretch (ContrastStretch)
    bool widthInvert = false;              ///< width scalar: high = thin lines
    std::array<double, 2> widthRange{0, 1}; ///< width scalar mapped onto narrowest … widest
    std::array<double, 2> roiRange{0, 1};   ///< ROI post-mask: kept range
    std::array<double, 2> colorRange{0, 1}; ///< colour scalar mapped onto the colormap
    /// The grids asked for (OutputGrids.h, GridWhen::Asked): `input` (the input texture),
    /// `tangent` (the unit flow direction), `velocity` (how the lines move, world units per
    /// second, for renderers' motion blur), each level's `density_w<k>` / `halo_w<k>` (spots).
    OutputGridSet grids;
    /// With the velocity grid: > 0 = the unit flow direction times this speed (a loop: the speed at
    /// which its comets or ripples travel); 0 = the field's own velocity times velocityScale (a
    /// still, or one frame of an unsteady sequence).
    double velocitySpeed = 0.0;
    double velocityScale = 1.0;
    double inputRadius = 1.0;  ///< spots' `input` grid: the narrowest line radius (output voxels)
    double haloScale = 2.0;
    int threads = 0;           ///< compositing a loop's frames (0 = all cores)

    bool writes(OutputGrid g) const { return grids.has(g); }
    /// Spots: each level's lines and halos are written (`density_w<k>`, `halo_w<k>`).
    bool series() const { return grids.has(OutputGrid::LevelLines); }
    /// Texture channels C: 1 for noise, 2K for spots.
    int textureChannels() const { return spots ? 2 * levels : 1; }
    /// Spot stills and comet loops compose their frames as the bricks arrive.
    bool composesOnArrival() const { return spots && (frames == 1 || comets); }
    /// Channels a brick delivers: C, 3C + 2 for a ripple loop, frames · C for a comet loop.
    int rawChannels() const
    {
        if (frames > 1 && comets) return frames * textureChannels();
        return frames > 1 ? 3 * textureChannels() + 2 : textureChannels();
    }
};

/// The scalars and textures compositing reads; empty ScalarFields are unused.
struct CompositeInputs
{
    ScalarField width;   ///< spots: picks the width level per voxel (with 2+ levels)
    ScalarField roi;     ///< region of interest, post-mask
    ScalarField color;   ///< colour scalar (needs `colormap`)
    const Colormap* colormap = nullptr;
    NoiseBrickSource* noise = nullptr; ///< noise bakes writing `input`: the bricks' noise
    const SpotSet* spots = nullptr;    ///< spot bakes writing `input`: the spots
};

class Compositor
{
public:
    /// @throw lic::InputError for inputs the settings need but lack.
    Compositor(const CompositeSettings& settings, CompositeInputs inputs, const VelocityField& field,
               const OutputDomain& domain, const BrickLayout& layout);

    /// Spot stills: hand every leaf to `sealer` as soon as its brick is consumed (LeafSealer.h), so
    /// that frame(1)'s grids hold topology-only leaves. Loops: the leaves of the grids every frame
    /// shares (colour, scalar, tangent...), compressed once for every frame file; a comet loop
    /// also every frame's density, halo and level leaves (each frame's under its grid's name, told
    /// apart by their tags), so the loop holds its frames compressed. Call before
    /// the first consume(). Returns false, and seals nothing, for other bakes (a gather engine's
    /// still composes its leaves at the end) and when no grid would be sealed.
    bool sealLeaves(LeafSealer* sealer);
    /// Turn a finished brick into leaves. Thread-safe (called from the brick's worker).
    void consume(const BrickChannels& bricks);
    /// After the last brick: merge the per-brick statistics in brick order (deterministic).
    void finish();
    /// A distributed bake's per-brick statistics, before finish(): pack those of bricks `ids`
    /// (this process's), and install those another process packed (exact bits, so every process
    /// merges the same numbers in the same brick order).
    std::string packMoments(const std::vector<std::size_t>& ids) const;
    /// @throw lic::Error for a malformed message or a brick id out of range.
    void unpackMoments(const std::string& bytes);
    /// Statistics of the raw frame-1 density over the active voxels (noise bakes).
    const ChannelStats& rawStats() const { return mRaw; }

    /// The grids of frame f (1-based) in file order (OutputGrids.h): density (+ halo and, with
    /// the level series, each level's lines and halos), then the grids every frame shares. The static grids are built on
    /// the first call and shared by every frame. The last frame takes the per-voxel data over in
    /// place, so call frames in order 1 … N.
    openvdb::GridPtrVec frame(int f);

private:
    struct SpotVoxel
    {
        float density = 0, halo = 0;
        float lines[4] = {}, halos[4] = {};
    };
    /// Lines and halos of each level normalised by their peaks (halo ≥ line), blended by width,
    /// times the ROI post-mask. `raw(c)` gives texture channel c's convolved value.
    template<typename Raw>
    SpotVoxel composeSpots(const Raw& raw, float widthT, float roi) const;
    void consumeBlock(const BrickChannels& bc, std::size_t i, Moments& moments);
    /// A comet loop's block being consumed: the voxels its sparse bound leaves (candidates, in
    /// voxel order) with their width and ROI, then every frame's values of each, frame-major
    /// ([frame][value][candidate]), and whether line or halo shows in some frame.
    struct LoopStage
    {
        std::array<std::uint16_t, 512> off;
        std::array<float, 512> widthT, roi;
        std::array<std::uint8_t, 512> shows;
        std::uint32_t candidates = 0;
        std::vector<float> values;
    };
    /// Line or halo shows (a kept voxel).
    static bool showsIn(const SpotVoxel& sv) { return sv.density > kSparseEpsilon || sv.halo > kSparseEpsilon; }
    /// Whether a spot voxel is kept (line or halo shows in some frame); a still's final values are
    /// stored here.
    template<typename Raw>
    bool keepSpotVoxel(const Raw& raw, float widthT, float roi, std::size_t b, const openvdb::Coord& origin,
                       openvdb::Index off);
    /// A kept voxel's other grids: raw channels, width and ROI (if written), the static grids.
    /// `b`, `origin`: the block of the brick's i-th block and its origin.
    void keepVoxel(const BrickChannels& bc, std::size_t i, std::size_t b, const openvdb::Coord& origin,
                   openvdb::Index off, float widthT, float roi, const NoiseTexture* noise);
    /// A comet loop: every frame of the stage's candidates composed, a frame at a time.
    void composeLoopBlock(const BrickChannels& bc, std::size_t i, LoopStage& stage) const;
    /// Values per voxel and frame of a comet loop: density, halo (+ each level's line and halo).
    int loopValues() const { return 2 + (mSettings.series() ? 2 * mSettings.levels : 0); }
    /// The name of loop value v's grid (density, halo, `density_w<k>`, `halo_w<k>`).
    std::string loopValueName(int v) const;
    /// Store the shown candidates' values of a consumed block in mLoopBlocks[b] (sealed: their
    /// leaves' tags).
    void keepLoopBlock(std::size_t b, const LoopStage& stage);
    struct LoopBlock;
    /// Seal every frame's leaves of a consumed block (grid = the loop value), keeping their tags.
    void sealLoopBlock(std::size_t b, const LoopStage& stage, LoopBlock& lb);
    /// A comet loop's frame f leaves (density, halo, levels) from mLoopBlocks, on every core.
    void composeLoopLeaves(int f, LeafSet<openvdb::FloatGrid>& density, LeafSet<openvdb::FloatGrid>& halo,
                           std::vector<LeafSet<openvdb::FloatGrid>>& lines,
                           std::vector<LeafSet<openvdb::FloatGrid>>& halos);
    /// The grids every frame shares (input, tangent, velocity, colour, scalar) at one voxel: each
    /// grid's fill.
    void addStatic(std::size_t b, const openvdb::Coord& origin, openvdb::Index off, const openvdb::Coord& ijk,
                   const NoiseTexture* noise);
    /// A loop frame's (or a noise still's) density and halo leaves, composed from the kept channels.
    void composeLeaves(int f, LeafSet<openvdb::FloatGrid>& density, LeafSet<openvdb::FloatGrid>& halo,
                       std::vector<LeafSet<openvdb::FloatGrid>>& lines, std::vector<LeafSet<openvdb::FloatGrid>>& halos);
    void buildStatic();
    /// Whether this bake writes grid `row`.
    bool writes(const OutputGridRow& row) const;
    /// fn(row, set) for each grid every frame shares that this bake writes, in file order, while
    /// its leaves are held (before buildStatic()).
    template<typename Fn>
    void forEachShared(Fn&& fn);
    LeafSet<openvdb::FloatGrid>& floats(OutputGrid g) { return mShared[std::size_t(g)].floats; }
    LeafSet<openvdb::Vec3SGrid>& vectors(OutputGrid g) { return mShared[std::size_t(g)].vectors; }
    /// fn(index, name, set) for each grid of a spot still composed on arrival, in frame(1)'s order:
    /// the grids sealLeaves() seals. `name()` makes the grid's name (a string) when called.
    template<typename Fn>
    void forEachStillSet(Fn&& fn);

    CompositeSettings mSettings;
    CompositeInputs mInputs;
    const VelocityField& mField;
    const OutputDomain& mDomain;
    std::optional<SpotTexture<1>> mInputSpots; // the `input` grid of a spot bake

    // Per-voxel data kept until the frames are written.
    std::vector<LeafSet<openvdb::FloatGrid>> mRawLeaves;  // loops and noise: the brick's channels
    LeafSet<openvdb::FloatGrid> mWidthLeaves, mRoiLeaves;  // loops: width blend t, ROI post-mask
    /// Spot stills: the final values (lines and halos per level with the series), composed as
    /// the bricks arrive.
    struct SpotFrame
    {
        LeafSet<openvdb::FloatGrid> density, halo;
        std::vector<LeafSet<openvdb::FloatGrid>> lines, halos;
    };
    SpotFrame mStill;
    /// Comet loops: per block, the voxels some frame shows and every frame's final values,
    /// frame-major ([frame][value][kept voxel], loopValues() values). Composed as the bricks
    /// arrive, like a still, but kept compact (a block's kept voxels are ~1/4 of its 512, and a
    /// leaf per frame and grid would hold all 512): each frame's leaves are made when it is
    /// written and freed after, so the frames in flight reuse the same memory.
    struct LoopBlock
    {
        openvdb::util::NodeMask<3> kept;
        std::unique_ptr<float[]> values;
        /// Sealed (sealLeaves): instead of the values, each frame's and value's leaf tag,
        /// frame-major ([frame][value]).
        std::unique_ptr<std::uint32_t[]> tags;
        std::uint32_t count = 0;
    };
    std::vector<LoopBlock> mLoopBlocks;
    /// The grids every frame shares, by OutputGrid: the set of the row's type is used.
    struct SharedLeaves
    {
        LeafSet<openvdb::FloatGrid> floats;
        LeafSet<openvdb::Vec3SGrid> vectors;
    };
    std::array<SharedLeaves, kOutputGridCount> mShared;
    std::vector<FramePhase> mPhases; // a loop's frames 1 … N (ripple phases)
    /// The largest 1 / peak over every line and halo level (composeSpots' factors): a voxel whose
    /// raw channels times it stay clear below kSparseEpsilon shows in no frame.
    float mMaxInvPeak = 0.0f;
    openvdb::GridPtrVec mStatic;
    bool mStaticBuilt = false;
    LeafSealer* mSealer = nullptr;
    bool mSealFrames = false; ///< a comet loop: mSealer also takes every frame's own leaves (sealLoopBlock)

    std::vector<Moments> mMoments; // per brick
    ChannelStats mRaw;
};

} // namespace lic

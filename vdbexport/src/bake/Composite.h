// Stage 6 of a bake: composite a brick. Each finished brick's channels become VDB leaf nodes
// right away (lines and halos normalised, width blended, region-of-interest post-mask, colour,
// tangent, input; voxels whose line and halo are both ~0 left inactive), and the brick's buffers
// go back to its worker. What needs the whole volume is gathered cheaply: the noise contrast from
// per-brick moments merged in brick order, and a loop's frames composed leaf by leaf at write time
// from the ripple sums kept per voxel. Memory: the output grids themselves, never a dense array
// over the volume.
#pragma once

#include "Input.h"
#include "Plan.h"
#include "Scalars.h"

#include "lic/engine/Bricks.h"
#include "lic/composite/Colormap.h"
#include "lic/composite/Contrast.h"
#include "lic/engine/Engine.h"
#include "lic/field/Field.h"
#include "lic/texture/Spots.h"

#include <openvdb/openvdb.h>

#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport::pipeline {

/// Voxels of a spot bake whose line and halo are both at most this stay inactive (1% of a line
/// core: invisible in any renderer, and well below the raycaster's halo threshold of 0.05).
constexpr float kSparseEpsilon = 0.01f;

/// The leaves of one output grid, one slot per domain block, filled as bricks finish (a brick
/// owns its blocks, so slots are written without locks).
template<typename GridT>
class LeafSet
{
public:
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;

    void init(std::size_t blocks)
    {
        mLeaves.clear();
        mLeaves.resize(blocks);
    }
    bool enabled() const { return !mLeaves.empty(); }
    LeafT* at(std::size_t b) const { return mLeaves[b].get(); }
    /// A new leaf (all inactive) for block b at `origin`.
    LeafT& make(std::size_t b, const openvdb::Coord& origin)
    {
        mLeaves[b] = std::make_unique<LeafT>(origin, openvdb::zeroVal<ValueT>(), false);
        return *mLeaves[b];
    }
    void drop(std::size_t b) { mLeaves[b].reset(); }
    /// Move every leaf into a new grid with the output transform; the set is empty afterwards.
    typename GridT::Ptr release(const lic::OutputDomain& domain, const std::string& name);

private:
    std::vector<std::unique_ptr<LeafT>> mLeaves;
};

/// Automatic or given ranges of the width and colour scalars (in their own units).
struct Ranges
{
    std::array<double, 2> width{0.0, 1.0};
    std::array<double, 2> color{0.0, 1.0};
};

/// A colormap by name, or from a value,r,g,b .csv file.
/// @throw lic::InputError for an unknown name or an unreadable or malformed file.
lic::Colormap loadColormap(const std::string& spec);

/// The recipe's width and colour ranges: given, or the automatic 1st–99th percentiles over
/// `blocks` (null = every block; `reduce` sums a distributed bake's histograms). Loads `cmap` when
/// the recipe colours by a scalar.
Ranges bakeRanges(const Recipe& recipe, ScalarSet& scalars, const lic::OutputDomain& domain,
                  std::optional<lic::Colormap>& cmap, const std::vector<std::uint32_t>* blocks = nullptr,
                  const HistogramReduce& reduce = {});

class Compositor
{
public:
    /// `cmap` is needed when the recipe colours by a scalar.
    Compositor(const Plan& plan, const lic::VelocityField& field, const lic::OutputDomain& domain,
               const lic::BrickLayout& layout, ScalarSet& scalars, Input& input, const lic::Colormap* cmap,
               const Ranges& ranges);

    /// Turn a finished brick into leaves. Thread-safe (called from the brick's worker).
    void consume(const lic::BrickChannels& bricks);
    /// After the last brick: merge the per-brick statistics in brick order (deterministic).
    void finish();
    /// A distributed bake's per-brick statistics, before finish(): pack those of bricks `ids`
    /// (this process's), and install those another process packed (exact bits, so every process
    /// merges the same numbers in the same brick order).
    std::string packMoments(const std::vector<std::size_t>& ids) const;
    /// @throw lic::Error for a malformed message or a brick id out of range.
    void unpackMoments(const std::string& bytes);
    /// Statistics of the raw frame-1 density over the active voxels (noise bakes).
    const lic::ChannelStats& rawStats() const { return mRaw; }

    /// The grids of frame f (1-based) in file order: density (+ halo and, with write_series, each
    /// level's lines and halos), then input, tangent, color, scalar. The static grids are built on
    /// the first call and shared by every frame. The last frame takes the per-voxel data over in
    /// place, so call frames in order 1 … N.
    openvdb::GridPtrVec frame(int f);

private:
    struct Moments
    {
        double sum = 0, sumSq = 0, count = 0;
        float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    };
    struct SpotVoxel
    {
        float density = 0, halo = 0;
        float lines[4] = {}, halos[4] = {};
    };
    /// Lines and halos of each level normalised by their peaks (halo ≥ line), blended by width,
    /// times the ROI post-mask. `raw(c)` gives texture channel c's convolved value.
    template<typename Raw>
    SpotVoxel composeSpots(const Raw& raw, float widthT, float roi) const;
    void consumeBlock(const lic::BrickChannels& bc, std::size_t i, Moments& moments);

    const Plan& mPlan;
    const lic::VelocityField& mField;
    const lic::OutputDomain& mDomain;
    ScalarSet& mScalars;
    Input& mInput;
    const lic::Colormap* mColormap;
    Ranges mRanges;
    ScalarField mWidthGrid, mRoiGrid, mColorGrid;
    std::optional<lic::SpotTexture<1>> mInputSpots; // write_input of a spot bake

    // Per-voxel data kept until the frames are written.
    std::vector<LeafSet<openvdb::FloatGrid>> mRawLeaves;  // loops and noise: the brick's channels
    LeafSet<openvdb::FloatGrid> mWidthLeaves, mRoiLeaves;  // loops: width blend t, ROI post-mask
    LeafSet<openvdb::FloatGrid> mDensity, mHalo;           // spot stills: final
    std::vector<LeafSet<openvdb::FloatGrid>> mLines, mHalos; // spot stills with write_series
    LeafSet<openvdb::FloatGrid> mInputLeaves, mScalarLeaves;
    LeafSet<openvdb::Vec3SGrid> mTangentLeaves, mColorLeaves;
    openvdb::GridPtrVec mStatic;
    bool mStaticBuilt = false;

    std::vector<Moments> mMoments; // per brick
    lic::ChannelStats mRaw;
};

} // namespace vdbexport::pipeline

// One frame of a bake: the path every bake runs, a still, each frame of a loop (one convolution
// gives them all) and each frame of an unsteady sequence alike:
//   read the field (this process's share) → scalars and their ranges → input texture
//   → convolve brick by brick, compositing each brick as it finishes → merge the statistics.
// The drivers (bake() in Bake.cpp, bakeSequence() in Sequence.cpp) then write the frame's grids.
#pragma once

#include "bake/Distribute.h"
#include "bake/FieldShare.h"
#include "bake/Input.h"
#include "bake/Plan.h"

#include "lic/composite/Colormap.h"
#include "lic/composite/Compositor.h"
#include "lic/engine/Settings.h"
#include "lic/field/ScalarField.h"
#include "lic/util/Progress.h"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport::pipeline {

/// Automatic or given ranges of the width and colour scalars (in their own units).
struct Ranges
{
    std::array<double, 2> width{0.0, 1.0};
    std::array<double, 2> color{0.0, 1.0};
};

/// The recipe's width and colour ranges: given, or the automatic 1st–99th percentiles over
/// `blocks` (null = every block; `reduce` sums a distributed bake's histograms). Loads `cmap` when
/// the recipe colours by a scalar.
Ranges bakeRanges(const Recipe& recipe, lic::ScalarSet& scalars, const lic::OutputDomain& domain,
                  std::optional<lic::Colormap>& cmap, const std::vector<std::uint32_t>* blocks = nullptr,
                  const lic::HistogramReduce& reduce = {});

/// Where a frame's input texture comes from when it is not made from the recipe alone (an
/// unsteady sequence carries it along the flow from the previous frame).
using InputSource = std::function<Input(const Plan&, const FieldShare&, lic::ScalarSet&)>;

struct FrameOptions
{
    /// Fixed ranges (a sequence keeps its first frame's, so colours do not flicker); null = this
    /// frame's own.
    const Ranges* ranges = nullptr;
    /// The input texture; empty = makeInput() from the plan (this process's share of the spots).
    InputSource input;
    /// Called once the field is read, before anything is computed from it (a sequence checks that
    /// its frames agree). May throw lic::InputError.
    std::function<void(const FieldShare&)> onField;
    /// World units per second per unit of the field's velocity (a sequence's cache units); empty = 1.
    std::function<double(const FieldShare&)> velocityScale;
    /// Distributed: why every rank reads the whole field ("" = a part where the format allows).
    std::string wholeField;
    /// Distributed, a part read: field voxels to add to the part's margin, first a guess, then
    /// `partMargin(share, maxSpeed)` once the whole field's largest speed is known; the part is
    /// read again with that margin if the guess was short.
    int partMarginGuess = 0;
    std::function<int(const FieldShare&, double maxSpeed)> partMargin;
    /// Seal a spot still's leaves as its bricks finish (lic::Compositor::sealLeaves); FrameBake's
    /// `sealed` says whether it did.
    lic::LeafSealer* sealer = nullptr;
};

/// Whether a one-process bake may seal a spot still's leaves (FrameOptions::sealer): yes unless
/// the environment sets LICVDB_SEAL_LEAVES=0 (whole leaves; the same file).
bool sealingAllowed();

/// One frame baked up to its composited grids (call compositor->frame(f) to get them). Not
/// copyable or movable: the compositor refers to the field, domain and input held here.
class FrameBake
{
public:
    /// In a distributed bake every rank constructs one with its share (`job`); in one process the
    /// job's operations are no-ops.
    /// @throw lic::InputError for bad input (the field, scalars, …); lic::Cancelled.
    FrameBake(const Plan& plan, Job& job, lic::Progress& progress, FrameOptions options = {});
    FrameBake(const FrameBake&) = delete;
    FrameBake& operator=(const FrameBake&) = delete;

    FieldShare share;                            ///< the field, the domain, its bricks, this share
    std::unique_ptr<lic::ScalarSet> scalars;
    Ranges ranges;
    std::optional<lic::Colormap> cmap;
    Input input;
    std::uint64_t spotCount = 0;                 ///< spots of the whole bake (summed over the ranks)
    std::optional<lic::Compositor> compositor;
    lic::LicStats stats;                         ///< of the convolution of this share
    std::uint64_t shareVoxels = 0;               ///< active output voxels of this share
    int partMargin = 0;                          ///< field voxels added to the part's margin
    bool sealed = false;                         ///< the compositor seals leaves (FrameOptions::sealer)
    /// Seconds of the stages (read: from construction; input: ranges and texture).
    struct Times
    {
        double read = 0, input = 0, convolve = 0, compose = 0;
    } seconds;

    const lic::VelocityField& field() const { return *share.field; }
    const lic::OutputDomain& domain() const { return *share.domain; }
    const lic::BrickLayout& layout() const { return *share.layout; }
    /// The bricks this process convolves (the whole layout in one process).
    const lic::BrickLayout& mine() const { return mMine ? *mMine : *share.layout; }

private:
    void read(const FrameOptions& options);
    void scalarsAndRanges(const FrameOptions& options);
    void makeTexture(const FrameOptions& options);
    void convolve(lic::Progress& progress);
    void mergeStatistics();

    const Plan& mPlan;
    Job& mJob;
    std::optional<lic::BrickLayout> mMine;       ///< distributed: this rank's bricks
    std::vector<std::uint32_t> mMineBlocks;      ///< distributed: their blocks
};

/// A process's part of a distributed spot bake: the spots that can reach `share.mine`'s bricks,
/// and its own blocks (those of its bricks).
SpotShare spotShareOf(const Plan& plan, const FieldShare& share);

/// What compositing needs to know of a plan: the recipe's settings, free of the recipe.
lic::CompositeSettings compositeSettings(const Plan& plan, const Ranges& ranges);

} // namespace vdbexport::pipeline

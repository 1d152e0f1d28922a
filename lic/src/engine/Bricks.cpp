#include "lic/engine/Bricks.h"

#include "lic/engine/Engine.h"
#include "lic/util/Error.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace lic {

BrickLayout::BrickLayout(const OutputDomain& domain, int dim)
    : mDim(dim)
{
    if (dim < 8 || dim > 512 || dim % 8 != 0) {
        throw InputError("brick size " + std::to_string(dim) + " is out of range; expected a multiple of 8 in 8..512");
    }
    std::map<openvdb::Coord, std::size_t> index; // brick coordinate → brick, ordered x-major
    for (std::size_t b = 0; b < domain.blockCount(); ++b) {
        const openvdb::Coord& o = domain.blockOrigin(b);
        const openvdb::Coord key(detail::floorDiv(o[0], dim), detail::floorDiv(o[1], dim), detail::floorDiv(o[2], dim));
        index.try_emplace(key, 0);
    }
    mBricks.resize(index.size());
    std::size_t i = 0;
    for (auto& [key, slot] : index) {
        slot = i;
        const openvdb::Coord lo(key[0] * dim, key[1] * dim, key[2] * dim);
        mBricks[i].id = i;
        mBricks[i].box = openvdb::CoordBBox(lo, lo + openvdb::Coord(dim - 1));
        ++i;
    }
    for (std::size_t b = 0; b < domain.blockCount(); ++b) {
        const openvdb::Coord& o = domain.blockOrigin(b);
        Brick& brick = mBricks[index[openvdb::Coord(detail::floorDiv(o[0], dim), detail::floorDiv(o[1], dim), detail::floorDiv(o[2], dim))]];
        brick.blocks.push_back(std::uint32_t(b));
        brick.activeVoxels += domain.blockMask(b).countOn();
    }
    for (const Brick& b : mBricks) mMaxBlocks = std::max(mMaxBlocks, b.blocks.size());
}

BrickLayout BrickLayout::subset(const std::vector<std::size_t>& ids) const
{
    BrickLayout out(*this);
    out.mBricks.clear();
    out.mMaxBlocks = 0;
    for (std::size_t id : ids) {
        if (id >= mBricks.size()) {
            throw InputError("brick " + std::to_string(id) + " is not in a layout of " + std::to_string(mBricks.size()) +
                             " bricks");
        }
        out.mBricks.push_back(mBricks[id]);
        out.mMaxBlocks = std::max(out.mMaxBlocks, mBricks[id].blocks.size());
    }
    return out;
}

int defaultBrickDim(const LicSettings& settings)
{
    // Measured on the 128³ abc bake (docs/performance.md): 64 for kernels up to ~24 voxels;
    // longer kernels need larger bricks to keep the window tails (n samples past each end of a
    // line) a small part of each line. Powers of two, so power-of-two volumes split evenly.
    // The splat engine has no window tails at brick faces (a footprint crossing a face is
    // rasterised by each brick it reaches, from one trace), so it keeps 64³ for load balance.
    if (settings.engine == EngineType::Splat) return 64;
    return settings.length <= 24 ? 64 : 128;
}

int ghostMargin(const LicSettings& settings)
{
    // A line leaves the brick at most half a voxel past its box (nearest-voxel rounding), then
    // traces n more samples of arc h: ≤ n·h index units on any axis. Two more voxels cover the
    // trilinear lookup and the binomial filter's footprint.
    const double tail = double(settings.halfSamples()) * settings.step;
    return int(std::ceil(tail + 0.5)) + 2;
}

BrickIndex::BrickIndex(const OutputDomain& domain, const Brick& brick, int dim)
    : mOrigin(brick.box.min())
    , mDim(dim)
    , mNb(dim / OutputDomain::kBlockDim)
{
    mActive.assign(std::size_t(mNb) * mNb * mNb, OutputDomain::Mask());
    for (std::uint32_t b : brick.blocks) mActive[localBlock(domain.blockOrigin(b))] = domain.blockMask(b);
}

} // namespace lic

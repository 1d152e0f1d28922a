#include "lic/Bricks.h"

#include "lic/Engine.h"
#include "lic/Error.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace lic {

namespace {
int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
} // namespace

BrickLayout::BrickLayout(const OutputDomain& domain, int dim)
    : mDim(dim)
{
    if (dim < 8 || dim > 512 || dim % 8 != 0) {
        throw InputError("brick size " + std::to_string(dim) + " is out of range; expected a multiple of 8 in 8..512");
    }
    std::map<openvdb::Coord, std::size_t> index; // brick coordinate → brick, ordered x-major
    for (std::size_t b = 0; b < domain.blockCount(); ++b) {
        const openvdb::Coord& o = domain.blockOrigin(b);
        const openvdb::Coord key(floorDiv(o[0], dim), floorDiv(o[1], dim), floorDiv(o[2], dim));
        index.try_emplace(key, 0);
    }
    mBricks.resize(index.size());
    std::size_t i = 0;
    for (auto& [key, slot] : index) {
        slot = i;
        const openvdb::Coord lo(key[0] * dim, key[1] * dim, key[2] * dim);
        mBricks[i].box = openvdb::CoordBBox(lo, lo + openvdb::Coord(dim - 1));
        ++i;
    }
    for (std::size_t b = 0; b < domain.blockCount(); ++b) {
        const openvdb::Coord& o = domain.blockOrigin(b);
        Brick& brick = mBricks[index[openvdb::Coord(floorDiv(o[0], dim), floorDiv(o[1], dim), floorDiv(o[2], dim))]];
        brick.blocks.push_back(std::uint32_t(b));
        brick.activeVoxels += domain.blockMask(b).count();
    }
    for (const Brick& b : mBricks) mMaxBlocks = std::max(mMaxBlocks, b.blocks.size());
}

int defaultBrickDim(const LicSettings& settings)
{
    // Measured on the 128³ abc bake (docs/performance.md): 64 is the fastest for kernels up to
    // ~24 voxels; longer kernels need larger bricks to keep the window tails a small part of
    // each line.
    const double L = settings.length;
    if (L <= 24) return 64;
    if (L <= 48) return 96;
    return 128;
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

#include "lic/field/Bricks.h"

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

std::vector<std::size_t> BrickLayout::positions() const
{
    std::vector<std::size_t> out(mBricks.size());
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = i;
    return out;
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

BrickIndex::BrickIndex(const OutputDomain& domain, const Brick& brick, int dim)
    : mOrigin(brick.box.min())
    , mDim(dim)
    , mNb(dim / OutputDomain::kBlockDim)
{
    mActive.assign(std::size_t(mNb) * mNb * mNb, OutputDomain::Mask());
    for (std::uint32_t b : brick.blocks) mActive[localBlock(domain.blockOrigin(b))] = domain.blockMask(b);
}

} // namespace lic

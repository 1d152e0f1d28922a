// Bricks: the unit of work of every bake. The output domain is cut into cubes of whole 8³ blocks
// (the leaf nodes of the grids we write); each brick is convolved on its own, from the field and
// the input texture inside its ghost margin, with accumulators local to the brick. A brick's
// result depends only on the brick, so a bake is bit-identical for any thread count, any brick
// order and, later, any number of processes; and the memory of the convolution is bounded by
// threads × brick, not by the volume.
#pragma once

#include "lic/field/OutputDomain.h"

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace lic {

/// One brick: an axis-aligned cube of `dim`³ output voxels (dim a multiple of 8, aligned to
/// multiples of dim in index space) and the domain's active blocks inside it.
struct Brick
{
    std::size_t id = 0;                 ///< number in the whole domain's layout (x-major), kept by subset()
    openvdb::CoordBBox box;             ///< output voxels owned, inclusive; may reach past the domain
    std::vector<std::uint32_t> blocks;  ///< indices of the domain's blocks inside, ascending
    std::uint64_t activeVoxels = 0;     ///< active output voxels owned
};

/// The bricks of a domain, in a fixed order (x-major over the brick grid). Only bricks holding at
/// least one active voxel exist.
class BrickLayout
{
public:
    /// @param dim brick edge in output voxels: a multiple of 8 in [8, 512].
    /// @throw lic::InputError for a bad `dim`.
    BrickLayout(const OutputDomain& domain, int dim);

    int dim() const { return mDim; }
    std::size_t size() const { return mBricks.size(); }
    const Brick& operator[](std::size_t i) const { return mBricks[i]; }
    const std::vector<Brick>& bricks() const { return mBricks; }
    /// Largest number of blocks in one brick (sizes per-thread buffers).
    std::size_t maxBlocks() const { return mMaxBlocks; }
    /// 0 … size() − 1: the positions of every brick in this layout (not their ids).
    std::vector<std::size_t> positions() const;
    /// The bricks with these ids only (a process's share of a distributed bake), in the order
    /// given; each keeps its id, so results keyed by id do not depend on the share.
    /// @throw lic::InputError for an id that is not in the layout.
    BrickLayout subset(const std::vector<std::size_t>& ids) const;

private:
    int mDim;
    std::vector<Brick> mBricks;
    std::size_t mMaxBlocks = 0;
};

/// Dense local numbering of a brick's voxels: block-major (8³ blocks x-major inside the brick),
/// and inside a block the leaf offset. Arrays of `voxels()` entries map block by block onto leaves.
class BrickIndex
{
public:
    BrickIndex() = default;
    BrickIndex(const OutputDomain& domain, const Brick& brick, int dim);

    int blocksPerAxis() const { return mNb; }
    std::size_t voxels() const { return std::size_t(mNb) * mNb * mNb * OutputDomain::kBlockVoxels; }
    const openvdb::Coord& origin() const { return mOrigin; }

    /// Local index of an output voxel, or −1 when it is outside the brick or inactive.
    std::int64_t localOf(const openvdb::Coord& ijk) const
    {
        const unsigned x = unsigned(ijk[0] - mOrigin[0]), y = unsigned(ijk[1] - mOrigin[1]),
                       z = unsigned(ijk[2] - mOrigin[2]);
        if (x >= unsigned(mDim) || y >= unsigned(mDim) || z >= unsigned(mDim)) return -1;
        const std::size_t block = (std::size_t(x >> 3) * unsigned(mNb) + (y >> 3)) * unsigned(mNb) + (z >> 3);
        const std::size_t off = ((x & 7u) << 6) | ((y & 7u) << 3) | (z & 7u);
        return mActive[block].isOn(openvdb::Index(off)) ? std::int64_t(block * OutputDomain::kBlockVoxels + off) : -1;
    }
    /// True when the voxel lies inside the brick's box (active or not).
    bool inside(const openvdb::Coord& ijk) const
    {
        return unsigned(ijk[0] - mOrigin[0]) < unsigned(mDim) && unsigned(ijk[1] - mOrigin[1]) < unsigned(mDim) &&
               unsigned(ijk[2] - mOrigin[2]) < unsigned(mDim);
    }
    /// Local block index of the domain block with this origin.
    std::size_t localBlock(const openvdb::Coord& blockOrigin) const
    {
        const openvdb::Coord d = blockOrigin - mOrigin;
        return (std::size_t(d[0] >> 3) * unsigned(mNb) + std::size_t(d[1] >> 3)) * unsigned(mNb) +
               std::size_t(d[2] >> 3);
    }
    const OutputDomain::Mask& activeMask(std::size_t localBlock) const { return mActive[localBlock]; }

private:
    openvdb::Coord mOrigin;
    int mDim = 0, mNb = 0;
    std::vector<OutputDomain::Mask> mActive;
};

} // namespace lic

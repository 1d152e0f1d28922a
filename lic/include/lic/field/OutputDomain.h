// Geometry of a bake's output volume: the field's transform refined by `upsample`, and the set of
// active output voxels stored as 8³ blocks (the leaf layout of the grids we write).
#pragma once

#include "lic/field/Field.h"

#include <openvdb/openvdb.h>

#include <array>
#include <cstdint>
#include <vector>

namespace lic {

/// Output voxel j (per axis) has its centre at field index (j + ½)/K − ½, K = upsample, so field
/// voxel i is split exactly into output voxels K·i … K·i + K − 1 and both volumes cover the same
/// world box. An output voxel is active when the field voxel containing it is active.
///
/// Voxels are addressed by a dense "slot" number: block · 512 + offset within the 8³ block
/// (offset as openvdb::tree::LeafNode::coordToOffset), so per-voxel arrays of `slotCount()`
/// entries map one-to-one onto leaf nodes.
class OutputDomain
{
public:
    static constexpr int kLog2Block = 3;
    static constexpr int kBlockDim = 1 << kLog2Block;
    static constexpr int kBlockVoxels = kBlockDim * kBlockDim * kBlockDim;
    /// Active voxels of one block, by leaf offset (the mask type of the leaves we write).
    using Mask = openvdb::util::NodeMask<kLog2Block>;

    /// @param upsample output voxels per field voxel along each axis, in [1, 16].
    /// @throw lic::InputError for an upsample out of range or an output of more than 2^31 voxels.
    OutputDomain(const VelocityField& field, int upsample);
    /// The same domain from the field's transform, active bounding box and active topology alone
    /// (for a field too large to read whole: a distributed bake reads the topology first, and
    /// then only the values its bricks need).
    /// @throw lic::InputError as above.
    OutputDomain(const openvdb::math::Transform& fieldTransform, const openvdb::CoordBBox& fieldActiveBox,
                 const openvdb::MaskGrid& activity, int upsample);

    int upsample() const { return mUpsample; }
    const openvdb::math::Transform::Ptr& transform() const { return mTransform; }
    const AffineMap& map() const { return mMap; }
    /// Smallest edge of an output voxel, world units: the unit of `--length` and `--step`.
    double voxelSize() const { return mVoxelSize; }
    /// Bounding box of all output voxels, inclusive.
    const openvdb::CoordBBox& indexBBox() const { return mBBox; }
    /// The output voxels of a field's index box at `upsample` K: field voxel i holds output voxels
    /// K·i … K·i + K − 1 along each axis.
    static openvdb::CoordBBox outputBox(const openvdb::CoordBBox& fieldBox, int upsample)
    {
        const int K = upsample;
        const openvdb::Coord& lo = fieldBox.min();
        const openvdb::Coord& hi = fieldBox.max();
        return openvdb::CoordBBox(openvdb::Coord(lo[0] * K, lo[1] * K, lo[2] * K),
                                  openvdb::Coord(hi[0] * K + K - 1, hi[1] * K + K - 1, hi[2] * K + K - 1));
    }

    std::size_t blockCount() const { return mBlockOrigins.size(); }
    const openvdb::Coord& blockOrigin(std::size_t b) const { return mBlockOrigins[b]; }
    const Mask& blockMask(std::size_t b) const { return mMasks[b]; }
    std::size_t slotCount() const { return blockCount() * kBlockVoxels; }
    std::uint64_t activeVoxelCount() const { return mActiveVoxels; }

    static int offsetOf(const openvdb::Coord& ijk)
    {
        return ((ijk[0] & (kBlockDim - 1)) << (2 * kLog2Block)) +
               ((ijk[1] & (kBlockDim - 1)) << kLog2Block) + (ijk[2] & (kBlockDim - 1));
    }
    openvdb::Coord coordOf(std::size_t slot) const
    {
        const int off = int(slot % kBlockVoxels);
        return mBlockOrigins[slot / kBlockVoxels] +
               openvdb::Coord(off >> (2 * kLog2Block), (off >> kLog2Block) & (kBlockDim - 1),
                              off & (kBlockDim - 1));
    }
    bool isActive(std::size_t slot) const
    {
        return mMasks[slot / kBlockVoxels].isOn(openvdb::Index(slot % kBlockVoxels));
    }
    /// Slot of an output voxel, or −1 when it is outside or inactive.
    std::int64_t slotOf(const openvdb::Coord& ijk) const
    {
        const std::int64_t b = blockOf(ijk);
        if (b < 0) return -1;
        const int off = offsetOf(ijk);
        return mMasks[std::size_t(b)].isOn(openvdb::Index(off)) ? b * kBlockVoxels + off : -1;
    }
    /// Block index of the block containing ijk, or −1.
    std::int64_t blockOf(const openvdb::Coord& ijk) const
    {
        const int bx = (ijk[0] >> kLog2Block) - mBlockMin[0];
        const int by = (ijk[1] >> kLog2Block) - mBlockMin[1];
        const int bz = (ijk[2] >> kLog2Block) - mBlockMin[2];
        if (bx < 0 || by < 0 || bz < 0 || bx >= mBlockDim[0] || by >= mBlockDim[1] ||
            bz >= mBlockDim[2])
            return -1;
        return mBlockTable[(std::size_t(bx) * mBlockDim[1] + by) * mBlockDim[2] + bz];
    }
    /// Set mark[b] = 1 for every block b with a voxel in `box` (mark has blockCount() entries).
    void markBlocks(const openvdb::CoordBBox& box, std::vector<std::uint8_t>& mark) const;
    /// The indices b with mark[b] != 0, ascending.
    static std::vector<std::uint32_t> markedBlocks(const std::vector<std::uint8_t>& mark);

    /// Nearest output voxel of a continuous output-index position.
    static openvdb::Coord nearestVoxel(const openvdb::Vec3d& p)
    {
        return openvdb::Coord(detail::floorIndex(p[0] + 0.5), detail::floorIndex(p[1] + 0.5),
                              detail::floorIndex(p[2] + 0.5));
    }

    /// World position of an output voxel's centre.
    openvdb::Vec3d worldOf(const openvdb::Coord& ijk) const { return mMap.toWorld(ijk.asVec3d()); }

    /// Build a grid from a per-slot array (active voxels only; leaf voxels, no tiles), with the
    /// output transform. GridT is openvdb::FloatGrid (class fog volume) or openvdb::Vec3SGrid.
    /// With `keep`, only slots with keep[s] != 0 become active (a sparse bake), and blocks with no
    /// kept voxel get no leaf.
    template<typename GridT>
    typename GridT::Ptr makeGrid(const std::vector<typename GridT::ValueType>& slots,
                                 const std::string& name,
                                 const std::vector<std::uint8_t>* keep = nullptr) const;
    openvdb::FloatGrid::Ptr makeGrid(const std::vector<float>& slots, const std::string& name,
                                     const std::vector<std::uint8_t>* keep = nullptr) const
    {
        return makeGrid<openvdb::FloatGrid>(slots, name, keep);
    }

private:
    template<typename GridT>
    void init(const openvdb::math::Transform& fieldTransform, const openvdb::CoordBBox& fieldActiveBox,
              const GridT& activity);

    int mUpsample;
    openvdb::math::Transform::Ptr mTransform;
    AffineMap mMap;
    double mVoxelSize;
    openvdb::CoordBBox mBBox;
    openvdb::Coord mBlockMin;
    std::array<int, 3> mBlockDim{};
    std::vector<std::int64_t> mBlockTable; // dense over the bbox's blocks: index or −1
    std::vector<openvdb::Coord> mBlockOrigins;
    std::vector<Mask> mMasks;
    std::uint64_t mActiveVoxels = 0;
};

} // namespace lic

// Where the raycaster's trilinear samples read a grid's voxels: a table of pointers to the
// grid's own leaf buffers over the box the rays cross, one per 8³ block (render/Raycaster.cpp).
// The grids are marched where they are (Raycaster.cpp copies only the density and halo of a dense
// bake into dense arrays). Internal to lic/src/render.
#pragma once

#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

namespace lic::detail {

/// @brief The leaf-aligned 8³ blocks that cover a box of voxels (index space), x fastest, and
///        where the eight voxels of a cell lie in them.
class LeafLayout
{
public:
    static constexpr int kLog2 = 3; ///< OpenVDB's leaf: 8³ voxels, offset = x·64 + y·8 + z
    static constexpr int kDim = 1 << kLog2;

    LeafLayout() = default;
    /// @param box  the voxels that will be read (at most 2^31)
    explicit LeafLayout(const openvdb::CoordBBox& box)
        : mMin(box.min().x() & ~(kDim - 1), box.min().y() & ~(kDim - 1), box.min().z() & ~(kDim - 1))
    {
        for (int a = 0; a < 3; ++a) mCount[a] = ((box.max()[a] - mMin[a]) >> kLog2) + 1;
    }

    /// Index coordinates of the first block's first voxel.
    const openvdb::Coord& min() const { return mMin; }
    std::size_t blockCount() const { return std::size_t(mCount[0]) * std::size_t(mCount[1]) * std::size_t(mCount[2]); }
    openvdb::Coord blockOrigin(std::size_t b) const
    {
        const std::size_t nx = std::size_t(mCount[0]), ny = std::size_t(mCount[1]);
        return mMin.offsetBy(int(b % nx) << kLog2, int(b / nx % ny) << kLog2, int(b / (nx * ny)) << kLog2);
    }

    /// The blocks and offsets of the voxels u + (0,0,0), (1,0,0), (0,1,0), (1,1,0), (0,0,1),
    /// (1,0,1), (0,1,1), (1,1,1) (x fastest).
    struct Cell
    {
        std::uint32_t block[8];
        std::uint32_t offset[8];
    };

    /// @param u  the cell's lowest voxel relative to min(), ≥ 0; u + 1 must be in the box.
    /// Branch-free: a third of the cells straddle two or more blocks, in no pattern a branch
    /// predictor can follow.
    [[gnu::always_inline]] Cell cell(int ux, int uy, int uz) const
    {
        constexpr std::uint32_t m = kDim - 1;
        const std::uint32_t x[2] = {std::uint32_t(ux), std::uint32_t(ux) + 1}, y[2] = {std::uint32_t(uy), std::uint32_t(uy) + 1},
                            z[2] = {std::uint32_t(uz), std::uint32_t(uz) + 1};
        const std::uint32_t sy = std::uint32_t(mCount[0]), sz = sy * std::uint32_t(mCount[1]);
        std::uint32_t bx[2], by[2], bz[2], ox[2], oy[2], oz[2];
        for (int i = 0; i < 2; ++i) {
            bx[i] = x[i] >> kLog2;
            by[i] = (y[i] >> kLog2) * sy;
            bz[i] = (z[i] >> kLog2) * sz;
            ox[i] = (x[i] & m) << (2 * kLog2);
            oy[i] = (y[i] & m) << kLog2;
            oz[i] = z[i] & m;
        }
        Cell c;
        for (int k = 0; k < 8; ++k) {
            const int i = k & 1, j = (k >> 1) & 1, l = (k >> 2) & 1;
            c.block[k] = bx[i] + by[j] + bz[l];
            c.offset[k] = ox[i] + oy[j] + oz[l];
        }
        return c;
    }

private:
    openvdb::Coord mMin;
    int mCount[3] = {0, 0, 0};
};

/// @brief One grid's values over a LeafLayout: per block, a pointer to its leaf's buffer, or to
///        512 copies of the value of the tile (or background) that covers the block.
///
/// It copies no leaf: the tree must outlive the table and not change meanwhile. Reads are
/// thread-safe. Trees loaded out of core (delayed loading) are loaded here.
template<typename ValueT>
class LeafTable
{
public:
    LeafTable() = default;

    template<typename TreeT>
    LeafTable(const TreeT& tree, const LeafLayout& layout) : mData(layout.blockCount(), nullptr)
    {
        static_assert(TreeT::LeafNodeType::DIM == LeafLayout::kDim, "an 8³ leaf");
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mData.size()), [&](const auto& r) {
            openvdb::tree::ValueAccessor<const TreeT, false> acc(tree);
            for (std::size_t b = r.begin(); b != r.end(); ++b)
                if (const auto* leaf = acc.probeConstLeaf(layout.blockOrigin(b))) mData[b] = leaf->buffer().data();
        });
        // Blocks without a leaf: one constant block per distinct value (usually the background only).
        openvdb::tree::ValueAccessor<const TreeT, false> acc(tree);
        for (std::size_t b = 0; b < mData.size(); ++b) {
            if (!mData[b]) mData[b] = constant(acc.getValue(layout.blockOrigin(b)));
            else ++mLeaves;
        }
    }

    /// The values at a cell's eight voxels, in LeafLayout::Cell's order.
    [[gnu::always_inline]] void read(const LeafLayout::Cell& c, ValueT* v) const
    {
        for (int k = 0; k < 8; ++k) v[k] = mData[c.block[k]][c.offset[k]];
    }

    /// The blocks that hold a leaf.
    std::size_t leafBlocks() const { return mLeaves; }

    /// The blocks' values, for a reader that keeps the pointer in a register.
    const ValueT* const* blocks() const { return mData.data(); }

private:
    const ValueT* constant(const ValueT& value)
    {
        for (const auto& block : mConstant)
            if (std::memcmp(&block[0], &value, sizeof(ValueT)) == 0) return block.get();
        auto block = std::make_unique<ValueT[]>(std::size_t(1) << (3 * LeafLayout::kLog2));
        for (std::size_t i = 0; i < (std::size_t(1) << (3 * LeafLayout::kLog2)); ++i) block[i] = value;
        mConstant.push_back(std::move(block));
        return mConstant.back().get();
    }

    std::vector<const ValueT*> mData;
    std::vector<std::unique_ptr<ValueT[]>> mConstant;
    std::size_t mLeaves = 0;
};


} // namespace lic::detail

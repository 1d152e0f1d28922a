#include "lic/field/OutputDomain.h"

#include "lic/util/Error.h"

#include <tbb/parallel_for.h>

#include <array>
#include <sstream>

namespace lic {

OutputDomain::OutputDomain(const VelocityField& field, int upsample)
    : mUpsample(upsample)
{
    init(field.transform(), field.indexBBox(), field.grid());
}

OutputDomain::OutputDomain(const openvdb::math::Transform& fieldTransform, const openvdb::CoordBBox& fieldActiveBox,
                           const openvdb::MaskGrid& activity, int upsample)
    : mUpsample(upsample)
{
    init(fieldTransform, fieldActiveBox, activity);
}

void OutputDomain::markBlocks(const openvdb::CoordBBox& box, std::vector<std::uint8_t>& mark) const
{
    if (box.empty()) return;
    for (int x = box.min()[0] >> kLog2Block; x <= box.max()[0] >> kLog2Block; ++x)
        for (int y = box.min()[1] >> kLog2Block; y <= box.max()[1] >> kLog2Block; ++y)
            for (int z = box.min()[2] >> kLog2Block; z <= box.max()[2] >> kLog2Block; ++z) {
                const std::int64_t b = blockOf(openvdb::Coord(x << kLog2Block, y << kLog2Block, z << kLog2Block));
                if (b >= 0) mark[std::size_t(b)] = 1;
            }
}

std::vector<std::uint32_t> OutputDomain::markedBlocks(const std::vector<std::uint8_t>& mark)
{
    std::vector<std::uint32_t> out;
    for (std::size_t b = 0; b < mark.size(); ++b)
        if (mark[b]) out.push_back(std::uint32_t(b));
    return out;
}

template<typename GridT>
void OutputDomain::init(const openvdb::math::Transform& fieldTransform, const openvdb::CoordBBox& fb,
                        const GridT& grid)
{
    const int upsample = mUpsample;
    if (upsample < 1 || upsample > 16) {
        throw InputError("upsample " + std::to_string(upsample) + " is out of range; expected 1..16");
    }
    const int K = upsample;
    mTransform = fieldTransform.copy();
    mTransform->preTranslate(openvdb::Vec3d(0.5 / K - 0.5));
    mTransform->preScale(1.0 / K);
    mMap = AffineMap(*mTransform);
    const openvdb::Vec3d vs = mTransform->voxelSize();
    mVoxelSize = std::min({vs[0], vs[1], vs[2]});

    mBBox = outputBox(fb, K);
    const openvdb::Coord dim = mBBox.dim();
    const double total = double(dim[0]) * dim[1] * dim[2];
    if (total > double(1ull << 31)) {
        std::ostringstream msg;
        msg << "output volume of " << dim[0] << "x" << dim[1] << "x" << dim[2]
            << " voxels is too large (more than 2^31); lower --upsample or crop the field";
        throw InputError(msg.str());
    }

    mBlockMin = openvdb::Coord(mBBox.min()[0] >> kLog2Block, mBBox.min()[1] >> kLog2Block,
                               mBBox.min()[2] >> kLog2Block);
    const openvdb::Coord blockMax(mBBox.max()[0] >> kLog2Block, mBBox.max()[1] >> kLog2Block,
                                  mBBox.max()[2] >> kLog2Block);
    for (int a = 0; a < 3; ++a) mBlockDim[a] = blockMax[a] - mBlockMin[a] + 1;
    const std::size_t nBlocks = std::size_t(mBlockDim[0]) * mBlockDim[1] * mBlockDim[2];

    auto originOf = [&](std::size_t b) {
        const int bx = int(b / (std::size_t(mBlockDim[1]) * mBlockDim[2]));
        const int by = int((b / mBlockDim[2]) % mBlockDim[1]);
        const int bz = int(b % mBlockDim[2]);
        return openvdb::Coord((mBlockMin[0] + bx) << kLog2Block, (mBlockMin[1] + by) << kLog2Block,
                              (mBlockMin[2] + bz) << kLog2Block);
    };
    // Activity of every candidate block, in parallel; then number the active blocks in order.
    std::vector<Mask> masks(nBlocks);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nBlocks), [&](const auto& r) {
        auto acc = grid.getConstAccessor();
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            // The field voxel of each of the block's 8 coordinates per axis, and whether it is in the box.
            const openvdb::Coord origin = originOf(b);
            std::array<std::array<int, 8>, 3> f;
            std::array<std::array<bool, 8>, 3> in;
            for (int a = 0; a < 3; ++a)
                for (int i = 0; i < 8; ++i) {
                    const int c = origin[a] + i;
                    in[a][i] = c >= mBBox.min()[a] && c <= mBBox.max()[a];
                    f[a][i] = detail::floorDiv(c, K);
                }
            for (int off = 0; off < kBlockVoxels; ++off) {
                const int x = off >> 6, y = (off >> 3) & 7, z = off & 7;
                if (!(in[0][x] && in[1][y] && in[2][z])) continue;
                if (acc.isValueOn(openvdb::Coord(f[0][x], f[1][y], f[2][z]))) masks[b].setOn(openvdb::Index(off));
            }
        }
    });
    mBlockTable.assign(nBlocks, -1);
    for (std::size_t b = 0; b < nBlocks; ++b) {
        if (masks[b].isOff()) continue;
        mBlockTable[b] = std::int64_t(mBlockOrigins.size());
        mBlockOrigins.push_back(originOf(b));
        mMasks.push_back(masks[b]);
        mActiveVoxels += masks[b].countOn();
    }
}

template<typename GridT>
typename GridT::Ptr OutputDomain::makeGrid(const std::vector<typename GridT::ValueType>& slots,
                                           const std::string& name,
                                           const std::vector<std::uint8_t>* keep) const
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    std::vector<LeafT*> leaves(blockCount(), nullptr);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blockCount()), [&](const auto& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            auto* leaf = new LeafT(mBlockOrigins[b], openvdb::zeroVal<ValueT>(), false);
            const ValueT* src = slots.data() + b * kBlockVoxels;
            const std::uint8_t* kept = keep ? keep->data() + b * kBlockVoxels : nullptr;
            for (auto on = mMasks[b].beginOn(); on; ++on) {
                const openvdb::Index it = on.pos();
                if (!kept || kept[it]) leaf->setValueOn(it, src[it]);
            }
            if (leaf->isEmpty()) {
                delete leaf;
                leaf = nullptr;
            }
            leaves[b] = leaf;
        }
    });
    auto grid = GridT::create(openvdb::zeroVal<ValueT>());
    for (LeafT* leaf : leaves)
        if (leaf) grid->tree().addLeaf(leaf);
    grid->setTransform(mTransform->copy());
    grid->setName(name);
    if constexpr (std::is_floating_point_v<ValueT>) {
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    } else {
        grid->setVectorType(openvdb::VEC_INVARIANT); // unit directions
    }
    return grid;
}

template openvdb::FloatGrid::Ptr OutputDomain::makeGrid<openvdb::FloatGrid>(
    const std::vector<float>&, const std::string&, const std::vector<std::uint8_t>*) const;
template openvdb::Vec3SGrid::Ptr OutputDomain::makeGrid<openvdb::Vec3SGrid>(
    const std::vector<openvdb::Vec3s>&, const std::string&, const std::vector<std::uint8_t>*) const;

} // namespace lic

// A spot bake's leaves sealed as its bricks finish (lic/composite/LeafSealer.h): each leaf's record
// made at once, as the .vdb file will hold it (LeafNode::writeBuffers with the stream state
// writeVdbFile gives its grid), so the leaf's values can be dropped; writeVdbFile then writes these
// records for the grids' topology-only leaves. The file's bytes are the same as from whole leaves.
#pragma once

#include <lic/composite/LeafSealer.h>

#include <openvdb/openvdb.h>

#include <tbb/concurrent_vector.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace vdbexport::detail {

/// One leaf's record (LeafNode::writeBuffers' bytes) and what the grid's delayed-load table holds
/// for it: the mask-compression kind and the compressed block's size.
struct LeafRecord
{
    openvdb::Coord origin;
    std::string bytes;
    std::int64_t size = 0;
    std::int8_t kind = 0;
};

class SealedLeaves final : public lic::LeafSealer
{
public:
    /// One grid's records, in the order sealed (a topology-only leaf's transientData indexes them).
    struct Grid
    {
        std::string name;
        tbb::concurrent_vector<LeafRecord> records;
    };

    /// `half`: the grids will be written as half floats (GridBase::saveFloatAsHalf). Records are
    /// made with the data compression writeVdbFile gives such a grid: io::Archive's default flags,
    /// without ZIP for float grids (fog volumes, as lic::LeafSet makes them).
    explicit SealedLeaves(bool half) : mHalf(half) {}
    /// That data compression, for leaves of value type T.
    template<typename T>
    static std::uint32_t compression();

    void begin(const std::vector<std::string>& grids) override;
    std::uint32_t seal(int grid, const openvdb::FloatTree::LeafNodeType& leaf) override;
    std::uint32_t seal(int grid, const openvdb::Vec3STree::LeafNodeType& leaf) override;

    bool half() const { return mHalf; }
    /// The records of grid `name`, or null if none were sealed for it.
    const Grid* find(const std::string& name) const;
    /// The grids begin() named, in its order.
    std::vector<std::string> names() const;

private:
    template<typename LeafT>
    std::uint32_t sealLeaf(int grid, const LeafT& leaf);

    bool mHalf;
    std::vector<std::unique_ptr<Grid>> mGrids;
};

} // namespace vdbexport::detail

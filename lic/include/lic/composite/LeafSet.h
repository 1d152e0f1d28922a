// The leaves of one output grid, one slot per output-domain block, filled as bricks finish (a brick
// owns its blocks, so slots are written without locks), then moved into a grid.
#pragma once

#include "lic/composite/LeafSealer.h"
#include "lic/field/OutputDomain.h"

#include <openvdb/openvdb.h>

#include <memory>
#include <string>
#include <type_traits>
#include <vector>

namespace lic {

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
    /// The leaf of block b, made when the block gets its first kept voxel.
    LeafT& leaf(std::size_t b, const openvdb::Coord& origin)
    {
        LeafT* l = at(b);
        return l ? *l : make(b, origin);
    }
    void drop(std::size_t b) { mLeaves[b].reset(); }
    /// Block b's leaf becomes `leaf` (e.g. a sealed leaf's topology-only copy).
    void put(std::size_t b, std::unique_ptr<LeafT> leaf) { mLeaves[b] = std::move(leaf); }
    /// Hand block b's leaf (if any) to `sealer` as grid `grid`, and keep only its topology.
    void seal(std::size_t b, LeafSealer& sealer, int grid)
    {
        if (const LeafT* l = at(b); l && !l->isEmpty()) mLeaves[b] = topologyOnly(*l, sealer.seal(grid, *l, 0));
    }

    /// Move every non-empty leaf into a new grid named `name` with the output transform (fog
    /// volume for floats, invariant vectors for vec3s); the set is empty afterwards.
    typename GridT::Ptr release(const OutputDomain& domain, const std::string& name)
    {
        auto grid = GridT::create(openvdb::zeroVal<ValueT>());
        for (auto& leaf : mLeaves)
            if (leaf && !leaf->isEmpty()) grid->tree().addLeaf(leaf.release());
        mLeaves.clear();
        grid->setTransform(domain.transform()->copy());
        grid->setName(name);
        if constexpr (std::is_floating_point_v<ValueT>) {
            grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        } else {
            grid->setVectorType(openvdb::VEC_INVARIANT);
        }
        return grid;
    }

private:
    std::vector<std::unique_ptr<LeafT>> mLeaves;
};

} // namespace lic

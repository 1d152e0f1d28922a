// Sealed leaves: a spot bake's output leaves handed, as each brick finishes, to whoever will write
// them, which keeps what it needs (a file writer: the leaf's record as the file will hold it) so
// that the leaf's 512 values can be dropped at once. The grids then hold the leaves' topology only
// (origin and active mask), and the memory of a bake grows with its compressed output, not with
// its float leaves: a 1024³ sparse bake holds ~1 GiB of records instead of 6 GiB of leaves. A comet
// loop seals every frame's leaves of a grid (`density` …) under that one grid: each frame's
// topology-only leaves carry the tags of their own records.
#pragma once

#include <openvdb/openvdb.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace lic {

/// Takes finished leaves; implemented by the writer (vdbexport::detail::SealedLeaves).
class LeafSealer
{
public:
    virtual ~LeafSealer() = default;
    /// The grids whose leaves will be sealed, by name, before the first seal(); `grid` in seal()
    /// indexes this list. `streams`: how many files the leaves of a grid go to (a comet loop's
    /// frames; 1 otherwise).
    virtual void begin(const std::vector<std::string>& grids, int streams) = 0;
    /// Keep what the leaf's values will be needed for. Returns the number the leaf's topology-only
    /// copy carries (LeafNode::transientData) to find it again. Called from several threads at
    /// once, for different leaves. `stream` (0 … streams − 1): the file the leaf goes to, a hint
    /// for keeping the leaves written together close together.
    virtual std::uint32_t seal(int grid, const openvdb::FloatTree::LeafNodeType& leaf, int stream) = 0;
    virtual std::uint32_t seal(int grid, const openvdb::Vec3STree::LeafNodeType& leaf, int stream) = 0;
};

/// A topology-only leaf: `origin` and active mask `mask`, no values (OpenVDB's partial leaf: its
/// buffer is not allocated, LeafNode::isAllocated() is false), carrying `tag`.
template<typename LeafT>
std::unique_ptr<LeafT> topologyOnly(const openvdb::Coord& origin, const typename LeafT::NodeMaskType& mask,
                                    std::uint32_t tag)
{
    auto out = std::make_unique<LeafT>(openvdb::PartialCreate(), origin, openvdb::zeroVal<typename LeafT::ValueType>(),
                                       false);
    out->setValueMask(mask);
    out->setTransientData(tag);
    return out;
}

/// A leaf's topology-only copy: the same origin and active mask, carrying `tag`.
template<typename LeafT>
std::unique_ptr<LeafT> topologyOnly(const LeafT& leaf, std::uint32_t tag)
{
    return topologyOnly<LeafT>(leaf.origin(), leaf.getValueMask(), tag);
}

} // namespace lic

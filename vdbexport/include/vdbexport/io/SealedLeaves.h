// A spot bake's leaves sealed as its bricks finish (lic/composite/LeafSealer.h): each leaf's record
// made at once, as the .vdb file will hold it (LeafNode::writeBuffers with the stream state
// writeVdbFile gives its grid), so the leaf's values can be dropped; writeVdbFile then writes these
// records for the grids' topology-only leaves. The file's bytes are the same as from whole leaves.
// A loop's records (every frame's) are spooled to an unnamed file beside its output.
#pragma once

#include <lic/composite/LeafSealer.h>

#include <openvdb/openvdb.h>

#include <tbb/concurrent_vector.h>
#include <tbb/enumerable_thread_specific.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace vdbexport::detail {

/// One leaf's record (LeafNode::writeBuffers' bytes) and what the grid's delayed-load table holds
/// for it: the mask-compression kind and the compressed block's size. `length`: the record's bytes;
/// spooled records keep them in the spool file at `spoolAt` instead of in `bytes`.
struct LeafRecord
{
    openvdb::Coord origin;
    std::string bytes;
    std::int64_t size = 0;
    std::uint64_t spoolAt = 0;
    std::uint32_t length = 0;
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
    /// `spoolDir` (a loop's output directory): the records' bytes go to an unnamed file there
    /// (O_TMPFILE, else a named one removed at once) instead of memory, so a loop holds none of its
    /// frames; empty = in memory (a still: its records are about its one file's size).
    /// @throw lic::Error if the spool file cannot be made.
    explicit SealedLeaves(bool half, const std::string& spoolDir = {});
    ~SealedLeaves() override;
    SealedLeaves(const SealedLeaves&) = delete;
    SealedLeaves& operator=(const SealedLeaves&) = delete;
    /// That data compression, for leaves of value type T.
    template<typename T>
    static std::uint32_t compression();

    void begin(const std::vector<std::string>& grids, int streams) override;
    std::uint32_t seal(int grid, const openvdb::FloatTree::LeafNodeType& leaf, int stream) override;
    std::uint32_t seal(int grid, const openvdb::Vec3STree::LeafNodeType& leaf, int stream) override;

    /// Put every spooled record's bytes in the spool file: after the last seal(), before the first
    /// appendBytes() (each thread gathers a grid's records in a small buffer and writes it when
    /// full, so a loop spools with one system call per buffer instead of one per leaf).
    /// @throw lic::Error if the spool cannot be written (disk full).
    void flush();

    bool half() const { return mHalf; }
    /// Append the records' bytes to `out`, in order (read back from the spool if spooled; records
    /// that lie one after another there are read with one system call).
    /// @throw lic::Error if the spool cannot be read; std::logic_error before flush().
    void appendBytes(std::span<const LeafRecord* const> records, std::string& out) const;
    /// The records of grid `name`, or null if none were sealed for it.
    const Grid* find(const std::string& name) const;
    /// The grids begin() named, in its order.
    std::vector<std::string> names() const;

private:
    template<typename LeafT>
    std::uint32_t sealLeaf(int grid, const LeafT& leaf, int stream);
    /// A thread's records of one grid waiting for the spool, at [base, base + capacity) there.
    struct Pending
    {
        std::string bytes;
        std::uint64_t base = 0;
        std::size_t capacity = 0;
    };
    /// Where the record `bytes` goes in the spool (buffered in the thread's Pending of `grid` and
    /// `stream`).
    std::uint64_t spool(int grid, int stream, std::string_view bytes);
    void writeSpool(const Pending& p) const;
    void readSpool(std::uint64_t at, std::size_t length, std::string& out) const;

    bool mHalf;
    std::vector<std::unique_ptr<Grid>> mGrids;
    int mSpool = -1;                       ///< the spool file, or −1
    std::string mSpoolDir;                 ///< for messages
    std::atomic<std::uint64_t> mSpoolEnd{0}; ///< bytes reserved in the spool (fetch_add)
    std::size_t mPendingBytes = 0;           ///< each Pending's capacity (from the grid count)
    int mStreams = 1;
    tbb::enumerable_thread_specific<std::vector<Pending>> mPending; ///< per thread, [stream][grid]
    std::atomic<bool> mFlushed{true};        ///< no record waits in a Pending
};

} // namespace vdbexport::detail

// A .vdb file written with every leaf compressed once, on every core (detail::writeVdbFile).
//
// openvdb::io::Archive::writeGrid makes a grid's record on one thread, and compresses each leaf
// twice: once (in parallel) only to learn its compressed size for the delayed-load table in the
// grid's metadata, then again (serially, leaf after leaf) to write it. For a bake that is most of
// its write stage. Here a float or Vec3f grid's record is made as writeGrid makes it, step for
// step, but its leaves' bytes come first: each leaf's own LeafNode::writeBuffers writes into a
// chunk of leaves in memory, chunks on all cores, and the delayed-load table is read off those
// bytes (the size of each leaf's compressed block and its mask-compression kind). Then the
// metadata, transform and topology are written by OpenVDB as usual, then the chunks in order.
// A grid too big to hold compressed in memory is compressed twice after all, both passes on all
// cores: the first keeps only the table, the second streams the chunks to the file in order.
// Other grid types, and files whose names Archive would change or whose grids share a tree, are
// written by OpenVDB itself. The bytes are io::File::write's but for the file's random UUID
// (tests/unit/test_vdbio.cpp compares them); the record layout followed here is the same in
// OpenVDB 10 to 13.
#include "vdbexport/io/VdbWrite.h"
#include "vdbexport/io/SealedLeaves.h"
#include "vdbexport/io/AtomicWrite.h"

#include <lic/util/Error.h>

#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <span>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <type_traits>
#include <utility>

#include <fcntl.h>
#include <unistd.h>

namespace vdbexport::detail {

namespace {

namespace io = openvdb::io;

/// Leaves per chunk: a chunk is one task's work and one string (~80 KiB for dense float leaves).
constexpr std::size_t kChunkLeaves = 64;
/// Sealed records are written in runs of about this many bytes.
constexpr std::size_t kRunBytes = std::size_t(4) << 20;

/// A run of consecutive leaves' records (LeafNode::writeBuffers), and per leaf what the
/// delayed-load table holds: the mask-compression kind and the compressed block's size.
struct Chunk
{
    std::string bytes;
    std::vector<std::int8_t> masks;
    std::vector<std::int64_t> sizes;
};

/// The mask-compression kind, and the compressed block's size plus its 8-byte count, read off
/// the leaf's record written from `at`: the value mask, the kind, its inactive values and
/// selection mask, then the block's count (negative: stored uncompressed) and bytes.
template<typename ValueT, typename MaskT>
std::pair<std::int8_t, std::int64_t> parseRecord(std::string_view bytes, std::size_t at)
{
    std::size_t p = at + sizeof(typename MaskT::Word) * MaskT::WORD_COUNT;
    if (p >= bytes.size()) throw lic::Error("a leaf's record is shorter than its value mask");
    const auto kind = std::int8_t(bytes[p++]);
    if (kind == io::NO_MASK_AND_ONE_INACTIVE_VAL || kind == io::MASK_AND_ONE_INACTIVE_VAL) p += sizeof(ValueT);
    if (kind == io::MASK_AND_TWO_INACTIVE_VALS) p += 2 * sizeof(ValueT);
    if (kind == io::MASK_AND_NO_INACTIVE_VALS || kind == io::MASK_AND_ONE_INACTIVE_VAL ||
        kind == io::MASK_AND_TWO_INACTIVE_VALS)
        p += sizeof(typename MaskT::Word) * MaskT::WORD_COUNT;
    std::int64_t count = 0;
    if (p + sizeof count > bytes.size()) throw lic::Error("a leaf's record is shorter than its layout");
    std::memcpy(&count, bytes.data() + p, sizeof count);
    const std::int64_t block = count < 0 ? -count : count;
    if (p + sizeof count + std::size_t(block) != bytes.size())
        throw lic::Error("a leaf's record does not end with its compressed block");
    return {kind, block + std::int64_t(sizeof count)};
}

/// Append the leaf's record to `os` (its data compression and background set to `compression`
/// and `background`); returns what the delayed-load table holds for it: the mask-compression kind
/// and the compressed block's size.
template<typename LeafT>
std::pair<std::int8_t, std::int64_t> appendRecord(std::ostringstream& os, const LeafT& leaf, std::uint32_t compression,
                                                  const typename LeafT::ValueType& background, bool half)
{
    using ValueT = typename LeafT::ValueType;
    using MaskT = typename LeafT::NodeMaskType;
    const auto at = std::size_t(os.tellp());
    leaf.writeBuffers(os, half);
    const auto [kind, size] = parseRecord<ValueT, MaskT>(os.view(), at);
    // Archive's populateDelayedLoadMetadata computes the kind from the tree's background whatever
    // the flags; with mask compression on, the record holds that same kind.
    if (compression & io::COMPRESS_ACTIVE_MASK) return {kind, size};
    return {io::MaskCompress<ValueT, MaskT>(leaf.valueMask(), MaskT(), leaf.buffer().data(), background).metadata, size};
}

/// One grid's leaves, compressed a chunk at a time with the stream state writeBuffers sees.
template<typename GridT>
class LeafRecords
{
public:
    using TreeT = typename GridT::TreeType;
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename TreeT::ValueType;
    using MaskT = typename LeafT::NodeMaskType;

    LeafRecords(const GridT& grid, std::uint32_t compression, bool sizes)
        : mLeaves(grid.constTree())
        , mBackground(grid.constTree().background())
        , mCompression(compression)
        , mSizes(sizes)
        , mHalf(grid.saveFloatAsHalf())
    {
    }

    std::size_t leafCount() const { return mLeaves.leafCount(); }
    std::size_t chunkCount() const { return (leafCount() + kChunkLeaves - 1) / kChunkLeaves; }

    /// Leaf i's sealed record (a topology-only leaf: its transientData indexes `sealed`).
    const LeafRecord& sealed(std::size_t i, const SealedLeaves::Grid& sealed) const
    {
        const LeafT& leaf = mLeaves.leaf(i);
        const std::size_t r = leaf.transientData();
        if (leaf.isAllocated() || r >= sealed.records.size() || sealed.records[r].origin != leaf.origin())
            throw lic::Error("grid '" + sealed.name + "' mixes sealed leaves with others");
        return sealed.records[r];
    }

    Chunk make(std::size_t c) const
    {
        const std::size_t begin = c * kChunkLeaves, end = std::min(leafCount(), begin + kChunkLeaves);
        Chunk out;
        std::ostringstream os(std::ios::out | std::ios::binary);
        io::setDataCompression(os, mCompression);
        io::setGridBackgroundValuePtr(os, &mBackground);
        for (std::size_t i = begin; i < end; ++i) {
            const auto [kind, size] = appendRecord(os, mLeaves.leaf(i), mCompression, mBackground, mHalf);
            out.masks.push_back(kind);
            if (mSizes) out.sizes.push_back(size);
        }
        if (!os) throw lic::Error("could not compress a grid's leaves");
        out.bytes = std::move(os).str();
        return out;
    }

private:
    openvdb::tree::LeafManager<const TreeT> mLeaves;
    const ValueT mBackground;
    std::uint32_t mCompression;
    bool mSizes;
    bool mHalf;
};

/// io::Archive's writer with each float or Vec3f grid's leaves compressed once, in parallel.
class ParallelArchive : public io::Archive
{
public:
    using Fast = openvdb::TypeList<openvdb::FloatGrid, openvdb::Vec3SGrid>;

    ParallelArchive(std::uint64_t holdBytes, const SealedLeaves* sealed)
        : mHoldBytes(holdBytes)
        , mSealed(sealed)
    {
    }

    /// False when io::File::write must write the grids: a null grid, a name that Archive would
    /// change (empty or repeated), or a tree shared by two grids (an instance).
    static bool suits(const openvdb::GridCPtrVec& grids)
    {
        std::set<std::string> names;
        std::set<const openvdb::TreeBase*> trees;
        for (const auto& g : grids) {
            if (!g || g->getName().empty() || !names.insert(g->getName()).second) return false;
            if (!trees.insert(&g->baseTree()).second) return false;
        }
        return true;
    }

    void write(std::ostream& file, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& metadata) const
    {
        // The file-level stream state, as Archive::write sets it.
        io::StreamMetadata::Ptr streamMetadata = std::make_shared<io::StreamMetadata>();
        io::setStreamMetadataPtr(file, streamMetadata, /*transfer=*/false);
        io::setDataCompression(file, compression());
        io::setWriteGridStatsMetadata(file, isGridStatsMetadataEnabled());
        writeHeader(file, /*seekable=*/true);
        metadata.writeMeta(file);
        const std::int32_t count = std::int32_t(grids.size());
        file.write(reinterpret_cast<const char*>(&count), sizeof count);
        for (const auto& grid : grids) {
            io::GridDescriptor gd(grid->getName(), grid->type(), grid->saveFloatAsHalf());
            const bool done =
                sizesAsOpenVdb() && grid->apply<Fast>([&](const auto& g) { writeRecord(gd, g, file, streamMetadata); });
            if (!done && mSealed && mSealed->find(grid->getName()))
                throw lic::Error("grid '" + grid->getName() + "' is sealed but not written by licvdb's writer");
            if (!done) writeGrid(gd, grid, file, /*seekable=*/true);
            if (!file) return; // the caller checks the stream
        }
    }

private:
    /// Archive sizes the delayed-load table with its own compression flags and writes the leaves
    /// with the grid's (no ZIP for fog volumes and level sets): the sizes read off the written
    /// leaves are the table's when Blosc decides both, or when neither compresses.
    bool sizesAsOpenVdb() const
    {
        const std::uint32_t c = compression();
        return (c & io::COMPRESS_BLOSC) || !(c & io::COMPRESS_ZIP);
    }

    /// Archive::writeGrid's steps, with the leaves compressed first (see the file comment).
    /// `fileMeta` is the file's stream metadata, which `os` points at (and is left pointing at).
    template<typename GridT>
    void writeRecord(io::GridDescriptor& gd, const GridT& grid, std::ostream& os,
                     io::StreamMetadata::Ptr& fileMeta) const
    {
        // Stream metadata varies per grid: a copy of the file's. (The stream keeps a pointer to
        // the shared pointer: it must outlive the writes.)
        io::StreamMetadata::Ptr meta = std::make_shared<io::StreamMetadata>(*fileMeta);
        meta->setHalfFloat(grid.saveFloatAsHalf());
        meta->gridMetadata() = static_cast<const openvdb::MetaMap&>(grid);
        io::setStreamMetadataPtr(os, meta, /*transfer=*/false);

        gd.writeHeader(os);
        const std::int64_t offsetPos = std::int64_t(os.tellp());
        gd.writeStreamPos(os); // positions not known yet: rewritten at the end
        gd.setGridPos(os.tellp());
        setGridCompression(os, grid);

        const bool sizes = compression() & (io::COMPRESS_BLOSC | io::COMPRESS_ZIP);
        const LeafRecords<GridT> leaves(grid, io::getDataCompression(os), sizes);
        const std::size_t n = leaves.leafCount(), chunks = leaves.chunkCount();
        const SealedLeaves::Grid* sealed = sealedRecords(grid, os);
        const bool hold = grid.memUsage() <= mHoldBytes;
        std::vector<Chunk> made(sealed ? 0 : chunks);
        tbb::parallel_for(std::size_t(0), made.size(), [&](std::size_t c) {
            made[c] = leaves.make(c);
            if (!hold) std::string().swap(made[c].bytes); // streamed again below
        });

        // The grid's metadata with the delayed-load table, as writeGrid adds it.
        const auto copy = openvdb::ConstPtrCast<openvdb::GridBase>(grid.copyGrid()); // shallow
        auto table = std::make_shared<io::DelayedLoadMetadata>();
        if (n > 0) {
            table->resizeMask(n);
            if (sizes) table->resizeCompressedSize(n);
            auto entry = [&](std::size_t i, std::int8_t kind, std::int64_t size) {
                table->setMask(i, kind);
                if (sizes) table->setCompressedSize(i, size);
            };
            if (sealed) {
                for (std::size_t i = 0; i < n; ++i) {
                    const LeafRecord& r = leaves.sealed(i, *sealed);
                    entry(i, r.kind, r.size);
                }
            }
            for (std::size_t c = 0, i = 0; c < made.size(); ++c)
                for (std::size_t k = 0; k < made[c].masks.size(); ++k, ++i)
                    entry(i, made[c].masks[k], sizes ? made[c].sizes[k] : 0);
        }
        copy->insertMeta(openvdb::GridBase::META_FILE_DELAYED_LOAD, *table);
        if (io::getWriteGridStatsMetadata(os)) {
            if (sealed) addSealedStats(*copy, grid);
            else copy->addStatsMetadata();
            copy->insertMeta(openvdb::GridBase::META_FILE_COMPRESSION,
                             openvdb::StringMetadata(io::compressionToString(io::getDataCompression(os))));
        }
        copy->writeMeta(os);
        grid.writeTransform(os);
        grid.writeTopology(os);
        gd.setBlockPos(os.tellp());

        if (sealed) {
            writeSealed(leaves, *sealed, *mSealed, os);
        } else if (hold) {
            for (Chunk& c : made) {
                os.write(c.bytes.data(), std::streamsize(c.bytes.size()));
                std::string().swap(c.bytes);
            }
        } else {
            streamChunks(leaves, os);
        }
        gd.setEndPos(os.tellp());
        os.seekp(offsetPos, std::ios_base::beg);
        gd.writeStreamPos(os);
        gd.seekToEnd(os);
        io::setStreamMetadataPtr(os, fileMeta, /*transfer=*/false);
    }

    /// GridBase::addStatsMetadata's entries for a grid of topology-only leaves, read off their
    /// masks (OpenVDB 13's evalActiveVoxelBoundingBox gives every leaf a buffer), with
    /// file_mem_bytes as for the grid before sealing (the leaves' values counted).
    template<typename GridT>
    static void addSealedStats(openvdb::GridBase& copy, const GridT& grid)
    {
        using LeafT = typename GridT::TreeType::LeafNodeType;
        if (grid.constTree().activeTileCount() > 0)
            throw lic::Error("grid '" + grid.getName() + "' has sealed leaves and active tiles");
        openvdb::CoordBBox bbox;
        std::size_t n = 0;
        for (auto it = grid.constTree().cbeginLeaf(); it; ++it, ++n) {
            // From the mask alone (a leaf's value iterators touch its buffer in OpenVDB 13).
            if (bbox.isInside(it->getNodeBoundingBox())) continue;
            for (auto on = it->getValueMask().beginOn(); on; ++on) bbox.expand(it->offsetToGlobalCoord(on.pos()));
        }
        const LeafT whole(openvdb::Coord(0)), bare(openvdb::PartialCreate(), openvdb::Coord(0));
        const auto mem = openvdb::Int64(grid.memUsage() + n * (whole.memUsage() - bare.memUsage()));
        for (const char* key : {openvdb::GridBase::META_FILE_BBOX_MIN, openvdb::GridBase::META_FILE_BBOX_MAX,
                                openvdb::GridBase::META_FILE_MEM_BYTES, openvdb::GridBase::META_FILE_VOXEL_COUNT})
            copy.removeMeta(key);
        copy.insertMeta(openvdb::GridBase::META_FILE_BBOX_MIN, openvdb::Vec3IMetadata(bbox.min().asVec3i()));
        copy.insertMeta(openvdb::GridBase::META_FILE_BBOX_MAX, openvdb::Vec3IMetadata(bbox.max().asVec3i()));
        copy.insertMeta(openvdb::GridBase::META_FILE_MEM_BYTES, openvdb::Int64Metadata(mem));
        copy.insertMeta(openvdb::GridBase::META_FILE_VOXEL_COUNT, openvdb::Int64Metadata(openvdb::Int64(grid.activeVoxelCount())));
    }

    /// The sealed records of `grid` (null if it has none), checked against the stream state its
    /// leaves are written with here.
    template<typename GridT>
    const SealedLeaves::Grid* sealedRecords(const GridT& grid, std::ostream& os) const
    {
        const SealedLeaves::Grid* sealed = mSealed ? mSealed->find(grid.getName()) : nullptr;
        if (!sealed) return nullptr;
        using ValueT = typename GridT::ValueType;
        if (io::getDataCompression(os) != SealedLeaves::compression<ValueT>() || grid.saveFloatAsHalf() != mSealed->half()
            || grid.constTree().background() != openvdb::zeroVal<ValueT>())
            throw lic::Error("grid '" + grid.getName() + "' was sealed for another compression, precision or background");
        return sealed;
    }

    /// The sealed records of the grid's leaves, in the tree's order.
    template<typename GridT>
    static void writeSealed(const LeafRecords<GridT>& leaves, const SealedLeaves::Grid& sealed,
                            const SealedLeaves& records, std::ostream& os)
    {
        // Gathered into runs of ~4 MiB: a file stream writes small records through its 8 KiB
        // buffer, a system call each time it fills (and spooled records that lie together are
        // read back together).
        std::string run;
        run.reserve(kRunBytes + 65536);
        std::vector<const LeafRecord*> batch;
        std::size_t batchBytes = 0;
        const std::size_t n = leaves.leafCount();
        for (std::size_t i = 0; i < n && os; ++i) {
            const LeafRecord& r = leaves.sealed(i, sealed);
            batch.push_back(&r);
            batchBytes += r.length;
            if (batchBytes >= kRunBytes || i + 1 == n) {
                records.appendBytes(batch, run);
                os.write(run.data(), std::streamsize(run.size()));
                run.clear();
                batch.clear();
                batchBytes = 0;
            }
        }
    }

    /// The chunks made again on all cores and written in order, a few in flight at a time.
    template<typename GridT>
    static void streamChunks(const LeafRecords<GridT>& leaves, std::ostream& os)
    {
        const std::size_t chunks = leaves.chunkCount();
        const auto tokens = std::size_t(2 * std::max(1, tbb::this_task_arena::max_concurrency()));
        std::size_t next = 0;
        tbb::parallel_pipeline(
            tokens,
            tbb::make_filter<void, std::size_t>(tbb::filter_mode::serial_in_order,
                                                [&](tbb::flow_control& fc) -> std::size_t {
                                                    if (next == chunks) {
                                                        fc.stop();
                                                        return 0;
                                                    }
                                                    return next++;
                                                })
                & tbb::make_filter<std::size_t, std::string>(
                    tbb::filter_mode::parallel, [&](std::size_t c) { return leaves.make(c).bytes; })
                & tbb::make_filter<std::string, void>(tbb::filter_mode::serial_in_order, [&](const std::string& bytes) {
                      os.write(bytes.data(), std::streamsize(bytes.size()));
                  }));
    }

    std::uint64_t mHoldBytes;
    const SealedLeaves* mSealed;
};

} // namespace

template<typename T>
std::uint32_t SealedLeaves::compression()
{
    // ParallelArchive's flags (io::Archive's default) as setGridCompression leaves them: no ZIP
    // for fog volumes.
    const std::uint32_t c = io::Archive::DEFAULT_COMPRESSION_FLAGS;
    return std::is_floating_point_v<T> ? (c & ~std::uint32_t(io::COMPRESS_ZIP)) : c;
}

SealedLeaves::SealedLeaves(bool half, const std::string& spoolDir)
    : mHalf(half)
    , mSpoolDir(spoolDir.empty() ? "" : "'" + spoolDir + "'")
{
    if (spoolDir.empty()) return;
    // An unnamed file: nothing is left behind whatever becomes of the process. Without O_TMPFILE
    // (or with the test seam LICVDB_TEST_NO_O_TMPFILE=1), a named one removed at once.
    if (!noTmpfile()) mSpool = ::open(spoolDir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (mSpool < 0) {
        std::string name = (std::filesystem::path(spoolDir) / ".licvdb-spool-XXXXXX").string();
        mSpool = ::mkostemp(name.data(), O_CLOEXEC);
        if (mSpool >= 0) ::unlink(name.c_str());
    }
    if (mSpool < 0)
        throw lic::Error("cannot make a spool file for a loop's compressed leaves in " + mSpoolDir + " ("
                         + std::strerror(errno) + ")");
}

SealedLeaves::~SealedLeaves()
{
    if (mSpool >= 0) ::close(mSpool);
}

void SealedLeaves::writeSpool(const Pending& p) const
{
    for (std::size_t done = 0; done < p.bytes.size();) {
        const ssize_t n = ::pwrite(mSpool, p.bytes.data() + done, p.bytes.size() - done, off_t(p.base + done));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw lic::Error("cannot spool the compressed leaves of a loop to " + mSpoolDir + " ("
                             + (n < 0 ? std::strerror(errno) : "nothing written") + "; disk full?)");
        done += std::size_t(n);
    }
}

void SealedLeaves::readSpool(std::uint64_t at, std::size_t length, std::string& out) const
{
    const std::size_t start = out.size();
    out.resize(start + length);
    for (std::size_t done = 0; done < length;) {
        const ssize_t n = ::pread(mSpool, out.data() + start + done, length - done, off_t(at + done));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw lic::Error("cannot read back the spooled leaves of a loop in " + mSpoolDir + " ("
                             + (n < 0 ? std::strerror(errno) : "the spool file is short") + ")");
        done += std::size_t(n);
    }
}

std::uint64_t SealedLeaves::spool(int grid, int stream, std::string_view bytes)
{
    // Written where a fetch_add reserved room: any thread, no lock. A thread fills a Pending per
    // grid and stream (a loop's frame), so the leaves of one file's grid sealed one after another
    // by a thread lie one after another in the spool and are read back together.
    if (stream < 0 || stream >= mStreams) throw std::logic_error("SealedLeaves: stream out of range");
    if (mFlushed.load(std::memory_order_relaxed)) mFlushed.store(false, std::memory_order_relaxed);
    Pending& p = mPending.local()[std::size_t(stream) * mGrids.size() + std::size_t(grid)];
    if (p.bytes.size() + bytes.size() > p.capacity) {
        writeSpool(p);
        p.bytes.clear();
        p.capacity = std::max(mPendingBytes, bytes.size());
        p.base = mSpoolEnd.fetch_add(p.capacity);
    }
    const std::uint64_t at = p.base + p.bytes.size();
    p.bytes.append(bytes);
    return at;
}

void SealedLeaves::flush()
{
    if (mSpool < 0) return;
    for (std::vector<Pending>& grids : mPending)
        for (Pending& p : grids) {
            writeSpool(p);
            p = Pending{};
        }
    mFlushed.store(true);
}

void SealedLeaves::appendBytes(std::span<const LeafRecord* const> records, std::string& out) const
{
    if (mSpool < 0) {
        for (const LeafRecord* r : records) out += r->bytes;
        return;
    }
    if (!mFlushed.load(std::memory_order_relaxed)) throw std::logic_error("SealedLeaves: spooled records read before flush()");
    for (std::size_t i = 0; i < records.size();) {
        const std::uint64_t at = records[i]->spoolAt;
        std::uint64_t end = at + records[i]->length;
        std::size_t j = i + 1;
        for (; j < records.size() && records[j]->spoolAt == end; ++j) end += records[j]->length;
        readSpool(at, std::size_t(end - at), out);
        i = j;
    }
}

void SealedLeaves::begin(const std::vector<std::string>& grids, int streams)
{
    mGrids.clear();
    for (const std::string& name : grids) {
        mGrids.push_back(std::make_unique<Grid>());
        mGrids.back()->name = name;
    }
    if (streams < 1) throw std::logic_error("SealedLeaves: no streams");
    mStreams = streams;
    if (mSpool < 0) return;
    // About 4 MiB per thread whatever the count of grids and frames (a 24-frame loop of three
    // widths fills ~200 files' grids), at least a few leaves' records per write.
    const std::size_t buffers = grids.size() * std::size_t(streams);
    mPendingBytes = std::clamp((std::size_t(4) << 20) / std::max<std::size_t>(1, buffers), std::size_t(16) << 10,
                               std::size_t(1) << 20);
    mPending = tbb::enumerable_thread_specific<std::vector<Pending>>(buffers);
    mFlushed.store(true);
}

template<typename LeafT>
std::uint32_t SealedLeaves::sealLeaf(int grid, const LeafT& leaf, int stream)
{
    using ValueT = typename LeafT::ValueType;
    static const ValueT background = openvdb::zeroVal<ValueT>();
    // One stream per thread and value type, emptied for each leaf (a stream's construction costs
    // about as much as compressing a sparse leaf).
    thread_local std::ostringstream os(std::ios::out | std::ios::binary);
    os.str(std::string());
    os.clear();
    const std::uint32_t c = compression<ValueT>();
    io::setDataCompression(os, c);
    io::setGridBackgroundValuePtr(os, &background);
    LeafRecord r;
    r.origin = leaf.origin();
    std::tie(r.kind, r.size) = appendRecord(os, leaf, c, background, mHalf);
    if (!os) throw lic::Error("could not compress a leaf of grid '" + mGrids.at(std::size_t(grid))->name + "'");
    const std::string_view bytes = os.view();
    r.length = std::uint32_t(bytes.size());
    if (mSpool >= 0) r.spoolAt = spool(grid, stream, bytes);
    else r.bytes = bytes;
    auto& records = mGrids.at(std::size_t(grid))->records;
    const auto at = records.push_back(std::move(r));
    const auto index = std::size_t(at - records.begin());
    if (index > std::numeric_limits<std::uint32_t>::max()) throw lic::Error("too many leaves to seal");
    return std::uint32_t(index);
}

std::uint32_t SealedLeaves::seal(int grid, const openvdb::FloatTree::LeafNodeType& leaf, int stream)
{
    return sealLeaf(grid, leaf, stream);
}
std::uint32_t SealedLeaves::seal(int grid, const openvdb::Vec3STree::LeafNodeType& leaf, int stream)
{
    return sealLeaf(grid, leaf, stream);
}

const SealedLeaves::Grid* SealedLeaves::find(const std::string& name) const
{
    for (const auto& g : mGrids)
        if (g->name == name) return g.get();
    return nullptr;
}

std::vector<std::string> SealedLeaves::names() const
{
    std::vector<std::string> out;
    for (const auto& g : mGrids) out.push_back(g->name);
    return out;
}

void writeVdbFile(const std::string& path, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& fileMetadata,
                  std::uint64_t holdBytes, const SealedLeaves* sealed)
{
    if (!ParallelArchive::suits(grids)) {
        if (sealed) throw lic::Error("cannot write '" + path + "': sealed grids need licvdb's writer");
        openvdb::io::File file(path);
        file.write(grids, fileMetadata);
        file.close();
        return;
    }
    std::ofstream file(path, std::ios::out | std::ios::binary | std::ios::trunc);
    if (!file) throw lic::Error("cannot write '" + path + "' (" + std::strerror(errno) + ")");
    ParallelArchive(holdBytes, sealed).write(file, grids, fileMetadata);
    file.close();
}

} // namespace vdbexport::detail

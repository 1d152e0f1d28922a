// A .vdb file's grids written side by side (detail::writeVdbFile).
//
// openvdb::io::File::write writes a file's grids one after another, and each grid's record is made
// on one thread: its leaves are compressed twice (once to size the delayed-load table, once to
// write them), leaf after leaf. For a spot bake's two grids (density and halo) that is the whole
// of its write stage, ~0.7 s serial for the figure-12 set. Here every grid's record is made by
// OpenVDB's own io::Archive::writeGrid, on its own task: the first straight into the file, the
// others into memory, and those are appended in order. writeGrid records three stream positions
// in the grid's descriptor (grid, blocks, end) from the stream it writes to; in a buffer they are
// relative to the buffer's start, so they are moved by the buffer's place in the file. The rest of
// a record holds sizes, not positions. The bytes are io::File::write's but for the file's random
// UUID (tests/unit/test_vdbio.cpp compares them).
#include "vdbexport/io/VdbIO.h"

#include <lic/util/Error.h>

#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <streambuf>

namespace vdbexport::detail {

namespace {

/// Grids whose records are held in memory at once, at most (in-memory size): a bigger file is
/// written by io::File::write, one grid at a time, without the extra copy.
constexpr openvdb::Index64 kSideBySideBytes = openvdb::Index64(256) << 20;

/// A grid's record in memory: an output stream buffer over a string, reserved up front (the grid's
/// in-memory size bounds its compressed record, so the string does not grow by doubling and only
/// the bytes written are touched) and seekable within what is written (writeGrid goes back to
/// rewrite the descriptor's positions).
class RecordBuffer : public std::streambuf
{
public:
    explicit RecordBuffer(std::size_t reserve) { mBytes.reserve(reserve); }
    std::string take() { return std::move(mBytes); }

protected:
    std::streamsize xsputn(const char* s, std::streamsize n) override
    {
        const std::size_t count = std::size_t(n), over = std::min(count, mBytes.size() - mPos);
        mBytes.replace(mPos, over, s, over);
        mBytes.append(s + over, count - over);
        mPos += count;
        return n;
    }
    int_type overflow(int_type c) override
    {
        if (traits_type::eq_int_type(c, traits_type::eof())) return traits_type::not_eof(c);
        const char ch = traits_type::to_char_type(c);
        xsputn(&ch, 1);
        return c;
    }
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode which) override
    {
        const off_type base = dir == std::ios_base::beg ? 0 : dir == std::ios_base::cur ? off_type(mPos) : off_type(mBytes.size());
        const off_type to = base + off;
        if (!(which & std::ios_base::out) || to < 0 || to > off_type(mBytes.size())) return pos_type(off_type(-1));
        mPos = std::size_t(to);
        return pos_type(to);
    }
    pos_type seekpos(pos_type pos, std::ios_base::openmode which) override
    {
        return seekoff(off_type(pos), std::ios_base::beg, which);
    }

private:
    std::string mBytes;
    std::size_t mPos = 0; ///< where the next byte goes (≤ size: writeGrid seeks back, then to the end)
};

/// io::Archive's writer with the grids' records made side by side (see the file comment).
class SideBySideArchive : public openvdb::io::Archive
{
public:
    /// False (and nothing written) when io::File::write must be used instead: fewer than two
    /// grids, a name that Archive would change (empty or repeated), a tree shared by two grids
    /// (an instance), or records too big to hold in memory.
    static bool suits(const openvdb::GridCPtrVec& grids)
    {
        if (grids.size() < 2) return false;
        std::set<std::string> names;
        std::set<const openvdb::TreeBase*> trees;
        openvdb::Index64 bytes = 0;
        for (std::size_t i = 0; i < grids.size(); ++i) {
            const auto& g = grids[i];
            if (!g || g->getName().empty() || !names.insert(g->getName()).second) return false;
            if (!trees.insert(&g->baseTree()).second) return false;
            if (i > 0) bytes += g->memUsage();
        }
        return bytes <= kSideBySideBytes;
    }

    void write(std::ostream& file, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& metadata) const
    {
        namespace io = openvdb::io;
        // The file-level stream state, as Archive::write sets it.
        io::StreamMetadata::Ptr streamMetadata = std::make_shared<io::StreamMetadata>();
        io::setStreamMetadataPtr(file, streamMetadata, /*transfer=*/false);
        io::setDataCompression(file, compression());
        io::setWriteGridStatsMetadata(file, isGridStatsMetadataEnabled());
        writeHeader(file, /*seekable=*/true);
        metadata.writeMeta(file);
        const std::int32_t count = std::int32_t(grids.size());
        file.write(reinterpret_cast<const char*>(&count), sizeof count);

        // Grid 0 into the file, the others into buffers with the same stream state.
        const std::size_t n = grids.size();
        std::vector<std::string> records(n);
        std::vector<std::int64_t> offsetPos(n, 0);
        std::vector<io::GridDescriptor> descriptors;
        for (const auto& g : grids) descriptors.emplace_back(g->getName(), g->type(), g->saveFloatAsHalf());
        tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
            if (i == 0) {
                writeGrid(descriptors[0], grids[0], file, /*seekable=*/true);
                return;
            }
            RecordBuffer buffer(std::size_t(grids[i]->memUsage()) + (std::size_t(1) << 16));
            std::ostream os(&buffer);
            // (The stream keeps a pointer to this shared pointer: it must outlive the writes.)
            io::StreamMetadata::Ptr meta = std::make_shared<io::StreamMetadata>(*streamMetadata);
            io::setStreamMetadataPtr(os, meta, /*transfer=*/false);
            io::setDataCompression(os, compression());
            io::setWriteGridStatsMetadata(os, isGridStatsMetadataEnabled());
            std::ostringstream header(std::ios::out | std::ios::binary);
            descriptors[i].writeHeader(header);
            offsetPos[i] = std::int64_t(header.tellp()); // where writeGrid puts the positions
            writeGrid(descriptors[i], grids[i], os, /*seekable=*/true);
            if (!os) throw lic::Error("could not make the record of grid '" + grids[i]->getName() + "'");
            records[i] = buffer.take();
        });
        if (!file) return; // the caller checks the stream

        // Append the buffers, each descriptor's positions moved by where its buffer lands.
        for (std::size_t i = 1; i < n; ++i) {
            const std::int64_t base = std::int64_t(file.tellp());
            io::GridDescriptor& gd = descriptors[i];
            gd.setGridPos(gd.getGridPos() + base);
            gd.setBlockPos(gd.getBlockPos() + base);
            gd.setEndPos(gd.getEndPos() + base);
            std::ostringstream pos(std::ios::out | std::ios::binary);
            gd.writeStreamPos(pos);
            const std::string p = std::move(pos).str();
            std::string& r = records[i];
            if (offsetPos[i] < 0 || std::size_t(offsetPos[i]) + p.size() > r.size())
                throw lic::Error("the record of grid '" + grids[i]->getName() + "' is shorter than its descriptor");
            std::memcpy(r.data() + offsetPos[i], p.data(), p.size());
            file.write(r.data(), std::streamsize(r.size()));
            std::string().swap(r); // free it as soon as it is written
        }
    }
};

} // namespace

void writeVdbFile(const std::string& path, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& fileMetadata)
{
    if (!SideBySideArchive::suits(grids)) {
        openvdb::io::File file(path);
        file.write(grids, fileMetadata);
        file.close();
        return;
    }
    std::ofstream file(path, std::ios::out | std::ios::binary | std::ios::trunc);
    if (!file) throw lic::Error("cannot write '" + path + "' (" + std::strerror(errno) + ")");
    SideBySideArchive().write(file, grids, fileMetadata);
    file.close();
}

} // namespace vdbexport::detail

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

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>

namespace vdbexport::detail {

namespace {

/// Grids whose records are held in memory at once, at most (in-memory size): a bigger file is
/// written by io::File::write, one grid at a time, without the extra copy.
constexpr openvdb::Index64 kSideBySideBytes = openvdb::Index64(256) << 20;

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
            std::ostringstream os(std::ios::out | std::ios::binary);
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
            records[i] = std::move(os).str();
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

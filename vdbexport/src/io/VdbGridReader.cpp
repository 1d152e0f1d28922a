#include "VdbGridReader.h"

#include <openvdb/Exceptions.h>
#include <openvdb/io/Archive.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <istream>
#include <map>
#include <streambuf>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace vdbexport::detail {

namespace {

/// A read-only stream buffer over a file: a window of up to kWindow bytes read with pread, seeks
/// and tells answered from it (a seek outside it only moves the position; the next read fills
/// the window there).
class WindowBuf final : public std::streambuf
{
public:
    static constexpr std::size_t kWindow = std::size_t(1) << 20;

    WindowBuf(int fd, std::uint64_t size) : mFd(fd), mSize(size)
    {
        setg(mWindow.get(), mWindow.get(), mWindow.get());
    }

protected:
    int_type underflow() override
    {
        if (gptr() < egptr()) return traits_type::to_int_type(*gptr());
        const std::uint64_t pos = position();
        const std::size_t got = pread(mWindow.get(), std::min<std::uint64_t>(kWindow, mSize - std::min(pos, mSize)), pos);
        mBase = pos;
        setg(mWindow.get(), mWindow.get(), mWindow.get() + got);
        return got > 0 ? traits_type::to_int_type(*gptr()) : traits_type::eof();
    }

    std::streamsize xsgetn(char* s, std::streamsize n) override
    {
        std::streamsize done = 0;
        while (done < n) {
            if (const std::streamsize avail = egptr() - gptr(); avail > 0) {
                const std::streamsize k = std::min(avail, n - done);
                std::memcpy(s + done, gptr(), std::size_t(k));
                gbump(int(k));
                done += k;
                continue;
            }
            if (traits_type::eq_int_type(underflow(), traits_type::eof())) break;
        }
        return done;
    }

    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode which) override
    {
        const off_type from = dir == std::ios_base::beg ? 0 : dir == std::ios_base::cur ? off_type(position()) : off_type(mSize);
        return seekpos(pos_type(from + off), which);
    }

    pos_type seekpos(pos_type p, std::ios_base::openmode which) override
    {
        const off_type to = off_type(p);
        if (!(which & std::ios_base::in) || to < 0 || std::uint64_t(to) > mSize) return pos_type(off_type(-1));
        const std::uint64_t t = std::uint64_t(to);
        if (t >= mBase && t <= mBase + std::uint64_t(egptr() - eback())) {
            setg(eback(), eback() + (t - mBase), egptr());
        } else {
            mBase = t;
            setg(mWindow.get(), mWindow.get(), mWindow.get());
        }
        return p;
    }

private:
    std::uint64_t position() const { return mBase + std::uint64_t(gptr() - eback()); }

    /// Up to n bytes at file offset `at` (fewer at the end of the file or on an error).
    std::size_t pread(char* dst, std::size_t n, std::uint64_t at) const
    {
        std::size_t got = 0;
        while (got < n) {
            const ssize_t r = ::pread(mFd, dst + got, n - got, off_t(at + got));
            if (r < 0 && errno == EINTR) continue;
            if (r <= 0) break;
            got += std::size_t(r);
        }
        return got;
    }

    const int mFd;
    const std::uint64_t mSize;
    std::unique_ptr<char[]> mWindow = std::make_unique_for_overwrite<char[]>(kWindow);
    std::uint64_t mBase = 0; ///< file offset of the window's first byte
};

/// The archive's reading half, as io::File::open and io::File::readGrid use it.
class GridArchive final : public openvdb::io::Archive
{
public:
    using NameMap = std::multimap<openvdb::Name, openvdb::io::GridDescriptor>;
    using Named = NamedGridMap;

    /// Header, file-level stream state, metadata and grid descriptors (io::File::open).
    void open(std::istream& is)
    {
        readHeader(is);
        mStreamMeta = std::make_shared<openvdb::io::StreamMetadata>();
        mStreamMeta->setSeekable(true);
        openvdb::io::setStreamMetadataPtr(is, mStreamMeta, /*transfer=*/false);
        setFormatVersion(is);
        setLibraryVersion(is);
        setDataCompression(is);
        openvdb::MetaMap().readMeta(is);
        if (!inputHasGridOffsets()) return;
        for (std::int32_t i = 0, n = readGridCount(is); i < n; ++i) {
            openvdb::io::GridDescriptor gd;
            gd.read(is);
            mDescriptors.emplace(gd.gridName(), gd);
            gd.seekToEnd(is);
        }
    }

    bool random() const { return inputHasGridOffsets(); }
    const NameMap& descriptors() const { return mDescriptors; }

    /// io::File::findDescriptor: the first grid called `name`, or the one whose unique name is
    /// "name[N]".
    const openvdb::io::GridDescriptor* find(const std::string& name) const
    {
        using openvdb::io::GridDescriptor;
        const openvdb::Name unique = GridDescriptor::stringAsUniqueName(name);
        auto range = mDescriptors.equal_range(name);
        if (range.first == range.second) range = mDescriptors.equal_range(GridDescriptor::stripSuffix(unique));
        if (range.first == range.second) return nullptr;
        if (name == unique) return &range.first->second;
        for (auto it = range.first; it != range.second; ++it)
            if (it->second.uniqueName() == unique || it->second.uniqueName() == name) return &it->second;
        return nullptr;
    }

    /// io::File::readGrid(const GridDescriptor&): an instance's tree is left to the caller.
    openvdb::GridBase::Ptr read(const openvdb::io::GridDescriptor& gd, std::istream& is) const
    {
        using openvdb::io::GridDescriptor;
        if (!openvdb::GridBase::isRegistered(gd.gridType()))
            OPENVDB_THROW(openvdb::KeyError, "Cannot read grid " << GridDescriptor::nameAsString(gd.uniqueName())
                                                                 << ": grid type " << gd.gridType()
                                                                 << " is not registered");
        openvdb::GridBase::Ptr grid = openvdb::GridBase::createGrid(gd.gridType());
        grid->setSaveFloatAsHalf(gd.saveFloatAsHalf());
        gd.seekToGrid(is);
        Archive::readGrid(grid, gd, is);
        return grid;
    }

    void connect(const openvdb::io::GridDescriptor& gd, const Named& grids) const { connectInstance(gd, grids); }

private:
    openvdb::io::StreamMetadata::Ptr mStreamMeta;
    NameMap mDescriptors;
};

} // namespace

struct GridFileReader::Impl
{
    explicit Impl(const std::string& path) : fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC))
    {
        struct stat st{};
        if (fd < 0 || ::fstat(fd, &st) != 0)
            OPENVDB_THROW(openvdb::IoError, "could not open file " << path << " (" << std::strerror(errno) << ")");
        buf = std::make_unique<WindowBuf>(fd, std::uint64_t(st.st_size));
        stream = std::make_unique<std::istream>(buf.get());
        archive.open(*stream);
    }
    ~Impl()
    {
        if (fd >= 0) ::close(fd);
    }

    int fd;
    std::unique_ptr<WindowBuf> buf;
    std::unique_ptr<std::istream> stream;
    GridArchive archive;
};

GridFileReader::GridFileReader(const std::string& path) : mImpl(std::make_unique<Impl>(path)) {}

GridFileReader::~GridFileReader() = default;

bool GridFileReader::random() const { return mImpl->archive.random(); }

openvdb::GridBase::Ptr GridFileReader::readGrid(const std::string& name)
{
    using openvdb::io::GridDescriptor;
    const GridArchive& a = mImpl->archive;
    const GridDescriptor* gd = a.find(name);
    if (!gd) OPENVDB_THROW(openvdb::KeyError, "no grid named \"" << name << "\"");
    openvdb::GridBase::Ptr grid = a.read(*gd, *mImpl->stream);
    if (gd->isInstance()) { // io::File::readGridByName
        const GridDescriptor* parent = a.find(GridDescriptor::nameAsString(gd->instanceParentName()));
        if (!parent)
            OPENVDB_THROW(openvdb::KeyError, "missing instance parent \""
                                                 << GridDescriptor::nameAsString(gd->instanceParentName())
                                                 << "\" for grid " << GridDescriptor::nameAsString(gd->uniqueName()));
        if (openvdb::GridBase::Ptr p = a.read(*parent, *mImpl->stream)) grid->setTree(p->baseTreePtr());
    }
    return grid;
}

openvdb::GridPtrVec GridFileReader::readAllGrids()
{
    const GridArchive& a = mImpl->archive;
    openvdb::GridPtrVec out;
    GridArchive::Named named;
    for (const auto& [name, gd] : a.descriptors()) {
        out.push_back(a.read(gd, *mImpl->stream));
        named[gd.uniqueName()] = out.back();
    }
    for (const auto& [name, gd] : a.descriptors()) a.connect(gd, named);
    return out;
}

} // namespace vdbexport::detail

// Output files staged out of sight and made visible together: a bake's frames and its manifest.
#pragma once

#include <openvdb/openvdb.h>

#include <string>
#include <utility>
#include <vector>

namespace vdbexport {

namespace detail {
class SealedLeaves; // vdbexport/io/SealedLeaves.h
}

/// @brief Output files staged out of sight and made visible together (a bake's frames and its
///        manifest).
///
/// Each add*() writes a complete, checked file to an unnamed temporary file in the target's
/// directory (O_TMPFILE; a named `PATH.tmp-<pid>` where the file system lacks it) and records its
/// SHA-256. commit() takes an exclusive flock on each target directory, then links and renames
/// every file into place in the order added (a bake adds its frames, then its manifest: a manifest
/// on disk means its frames are): two processes committing to the same paths never interleave, so
/// the last commit wins whole. A process killed before commit() leaves no final file; with
/// O_TMPFILE no temporary either, and without it (a named PATH.tmp-PID) the next write of PATH
/// removes what a killed process left. The destructor discards whatever was not committed.
class OutputSet
{
    struct Staged
    {
        std::string path;
        int fd = -1;       ///< the unnamed temporary file
        std::string named; ///< or a named temporary
        std::string sha256;
    };

public:
    OutputSet() = default;
    ~OutputSet();
    OutputSet(const OutputSet&) = delete;
    OutputSet& operator=(const OutputSet&) = delete;

    /// A .vdb file written to its unseen temporary but not yet in a set: what writeVdb returns, so
    /// that several files can be written at once (on several threads) and added in a fixed order.
    /// Dropped without add(), it leaves nothing on disk.
    class Pending
    {
    public:
        Pending(Pending&& o) noexcept : mFile(std::move(o.mFile)) { o.mFile.fd = -1, o.mFile.named.clear(); }
        Pending& operator=(Pending&&) = delete;
        Pending(const Pending&) = delete;
        ~Pending() { discard(mFile); }

    private:
        friend class OutputSet;
        explicit Pending(Staged f) : mFile(std::move(f)) {}
        Staged mFile;
    };

    /// Write grids for `path` as addVdb does, not yet into any set. Safe to call on several threads
    /// at once for different paths (and grids only read: shared grids are fine).
    /// @throw as writeVdbAtomic.
    /// `sealed`: the records of grids whose leaves were sealed (detail::writeVdbFile).
    static Pending writeVdb(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata = {},
                            const detail::SealedLeaves* sealed = nullptr);
    /// Stage a file writeVdb wrote. @throw lic::Error if the set has a file for its path already.
    void add(Pending&& file);
    /// Stage grids for `path`, as writeVdbAtomic writes them (active tiles voxelized on copies,
    /// structure checked after writing): add(writeVdb(...)). @throw as writeVdbAtomic.
    void addVdb(const std::string& path, openvdb::GridPtrVec grids, const openvdb::MetaMap& fileMetadata = {},
                const detail::SealedLeaves* sealed = nullptr);
    /// Stage a text file for `path`. @throw as writeTextAtomic.
    void addText(const std::string& path, const std::string& text);
    /// SHA-256 (64 hex digits) of the bytes staged for `path`. @throw lic::Error if none.
    std::string sha256(const std::string& path) const;
    /// Move every staged file into place (see the class comment).
    /// @throw lic::Error if a link or rename fails; files committed before it stay.
    void commit();

private:
    void refuseTwice(const std::string& path) const;
    static Staged stage(const std::string& path);
    static std::string target(const Staged& f);
    static void finish(Staged& f);
    static void discard(Staged& f);
    std::vector<Staged> mFiles;
};

} // namespace vdbexport

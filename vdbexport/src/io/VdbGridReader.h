// Reading a .vdb file's grids with OpenVDB's own grid reader through a stream whose seeks and
// tells cost no system call (VdbReader's grid reads).
#pragma once

#include <openvdb/openvdb.h>

#include <memory>
#include <string>

namespace vdbexport::detail {

/// @brief The grids of one .vdb file, read as io::File reads them (io::Archive::readGrid on a
///        seekable stream: the same grids, metadata, transforms and trees), but through a stream
///        buffer that reads the file 1 MiB at a time with pread and answers seeks and tells from
///        that window.
///
/// io::File reads through a std::ifstream: its 8 KiB buffer makes a read per leaf, and OpenVDB
/// asks every leaf for its stream position (tellg), which std::filebuf answers with an lseek.
/// For a 17 MB velocity file that is some 19 000 system calls, most of the read's time on a
/// virtual machine. A file shorter than its records (truncated meanwhile) reads as truncated
/// here: nothing is mapped, so nothing can fault.
///
/// Files without grid offsets (format versions before 212) cannot be read a grid at a time:
/// random() is false and the caller reads them with io::File.
class GridFileReader
{
public:
    /// Opens `path` and reads its header, metadata and grid descriptors.
    /// @throw openvdb::IoError (not a VDB file, unreadable), std::exception for what OpenVDB throws.
    explicit GridFileReader(const std::string& path);
    ~GridFileReader();
    GridFileReader(const GridFileReader&) = delete;
    GridFileReader& operator=(const GridFileReader&) = delete;

    /// True if the file has grid offsets (every file OpenVDB has written since 2011).
    bool random() const;
    /// The grid `name` (or "name[N]" among repeated names), as io::File::readGrid(name) gives it:
    /// an instance shares its parent's tree. @throw openvdb::KeyError if the file has no such grid.
    openvdb::GridBase::Ptr readGrid(const std::string& name);
    /// Every grid, as io::File::getGrids() gives them (by name; instances connected).
    openvdb::GridPtrVec readAllGrids();

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace vdbexport::detail

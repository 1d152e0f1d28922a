// Writing a .vdb file as openvdb::io::File::write does, with each leaf compressed once and on
// every core (src/io/VdbWrite.cpp says how).
#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>

namespace vdbexport::detail {

class SealedLeaves; // vdbexport/io/SealedLeaves.h

/// Grids whose compressed leaves writeVdbFile holds in memory (in-memory size, at most): a bigger
/// grid's leaves are compressed twice, both times on all cores, and streamed to the file.
constexpr std::uint64_t kWriteHoldBytes = std::uint64_t(256) << 20;

/// Write `grids` and the file metadata to `path` as openvdb::io::File::write does, byte for byte
/// but for the file's random UUID, with each float and Vec3f grid's leaves compressed once and on
/// every core (src/io/VdbWrite.cpp); grids over `holdBytes` are compressed twice, as OpenVDB does,
/// but on every core. Falls back to io::File::write for a null grid, names Archive would change
/// (empty or repeated) and trees shared by grids (instances); other grid types are written by
/// OpenVDB's own io::Archive::writeGrid within the file.
/// Errors as io::File::write's (openvdb exceptions, lic::Error); a short write is the caller's
/// to find (OutputSet::writeVdb checks the structure written).
/// Grids with sealed leaves (SealedLeaves.h: topology-only leaves, their records in `sealed`, found
/// by grid name) are written from those records.
void writeVdbFile(const std::string& path, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& fileMetadata,
                  std::uint64_t holdBytes = kWriteHoldBytes, const SealedLeaves* sealed = nullptr);

} // namespace vdbexport::detail

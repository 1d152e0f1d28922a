// SHA-256 (FIPS 180-4), for the checksums a bake's manifest carries of the files it describes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace vdbexport {

/// Incremental SHA-256: update() with the bytes, then hex() for the lower-case hex digest.
class Sha256
{
public:
    Sha256();
    void update(const void* data, std::size_t bytes);
    /// The digest as 64 lower-case hex digits; ends the computation.
    std::string hex();

private:
    void block(const unsigned char* p);
    uint32_t mH[8];
    unsigned char mBuf[64];
    std::size_t mBufLen = 0;
    uint64_t mTotal = 0;
};

/// SHA-256 of the whole file open as `fd` (read with pread from offset 0), as hex.
/// @throw lic::Error if the file cannot be read.
std::string sha256OfFd(int fd);

/// SHA-256 of the file at `path`, as hex. @throw lic::Error if it cannot be read.
std::string sha256OfFile(const std::string& path);

} // namespace vdbexport

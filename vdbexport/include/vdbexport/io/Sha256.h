// SHA-256 (OpenSSL's EVP digest), for the checksums a bake's manifest carries of the files it describes.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

struct evp_md_ctx_st;

namespace vdbexport {

/// Incremental SHA-256: update() with the bytes, then hex() for the lower-case hex digest.
class Sha256
{
public:
    Sha256();
    ~Sha256();
    Sha256(const Sha256&) = delete;
    Sha256& operator=(const Sha256&) = delete;
    void update(const void* data, std::size_t bytes);
    /// The digest as 64 lower-case hex digits; ends the computation.
    std::string hex();

private:
    evp_md_ctx_st* mCtx; // EVP_MD_CTX
};

/// SHA-256 of the whole file open as `fd` (read with pread from offset 0), as hex.
/// @throw lic::Error if the file cannot be read.
std::string sha256OfFd(int fd);

/// SHA-256 of the file at `path`, as hex. @throw lic::Error if it cannot be read.
std::string sha256OfFile(const std::string& path);

} // namespace vdbexport

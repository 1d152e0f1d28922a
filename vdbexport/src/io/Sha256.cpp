#include "vdbexport/io/Sha256.h"

#include <lic/util/Error.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include <openssl/evp.h>

#include <fcntl.h>
#include <unistd.h>

namespace vdbexport {

namespace {

[[noreturn]] void fail(const char* what) { throw lic::Error(std::string("SHA-256 (OpenSSL) failed: ") + what); }

} // namespace

Sha256::Sha256()
    : mCtx(EVP_MD_CTX_new())
{
    if (!mCtx || EVP_DigestInit_ex(mCtx, EVP_sha256(), nullptr) != 1) {
        EVP_MD_CTX_free(mCtx);
        fail("init");
    }
}

Sha256::~Sha256() { EVP_MD_CTX_free(mCtx); }

void Sha256::update(const void* data, std::size_t bytes)
{
    if (EVP_DigestUpdate(mCtx, data, bytes) != 1) fail("update");
}

std::string Sha256::hex()
{
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int n = 0;
    if (EVP_DigestFinal_ex(mCtx, digest, &n) != 1) fail("final");
    static const char* digits = "0123456789abcdef";
    std::string out;
    for (unsigned int i = 0; i < n; ++i) {
        out.push_back(digits[digest[i] >> 4]);
        out.push_back(digits[digest[i] & 15]);
    }
    return out;
}

std::string sha256OfFd(int fd)
{
    Sha256 sha;
    std::vector<char> buf(1 << 20);
    off_t at = 0;
    for (;;) {
        const ssize_t n = ::pread(fd, buf.data(), buf.size(), at);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) throw lic::Error(std::string("cannot read a file to checksum it (") + std::strerror(errno) + ")");
        if (n == 0) break;
        sha.update(buf.data(), std::size_t(n));
        at += n;
    }
    return sha.hex();
}

std::string sha256OfFile(const std::string& path)
{
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw lic::Error("cannot open '" + path + "' to checksum it (" + std::strerror(errno) + ")");
    try {
        const std::string h = sha256OfFd(fd);
        ::close(fd);
        return h;
    } catch (...) {
        ::close(fd);
        throw;
    }
}

} // namespace vdbexport

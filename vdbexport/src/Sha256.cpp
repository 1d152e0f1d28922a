#include "vdbexport/Sha256.h"

#include <lic/Error.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

namespace vdbexport {

namespace {

constexpr uint32_t kK[64] = {
    0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5,
    0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174,
    0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
    0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967,
    0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85,
    0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
    0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
    0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2};

inline uint32_t rotr(uint32_t x, int n) { return (x >> n) | (x << (32 - n)); }

} // namespace

Sha256::Sha256()
    : mH{0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a, 0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19}
{}

void Sha256::block(const unsigned char* p)
{
    uint32_t w[64];
    for (int i = 0; i < 16; ++i)
        w[i] = uint32_t(p[4 * i]) << 24 | uint32_t(p[4 * i + 1]) << 16 | uint32_t(p[4 * i + 2]) << 8 | uint32_t(p[4 * i + 3]);
    for (int i = 16; i < 64; ++i) {
        const uint32_t s0 = rotr(w[i - 15], 7) ^ rotr(w[i - 15], 18) ^ (w[i - 15] >> 3);
        const uint32_t s1 = rotr(w[i - 2], 17) ^ rotr(w[i - 2], 19) ^ (w[i - 2] >> 10);
        w[i] = w[i - 16] + s0 + w[i - 7] + s1;
    }
    uint32_t a = mH[0], b = mH[1], c = mH[2], d = mH[3], e = mH[4], f = mH[5], g = mH[6], h = mH[7];
    for (int i = 0; i < 64; ++i) {
        const uint32_t t1 = h + (rotr(e, 6) ^ rotr(e, 11) ^ rotr(e, 25)) + ((e & f) ^ (~e & g)) + kK[i] + w[i];
        const uint32_t t2 = (rotr(a, 2) ^ rotr(a, 13) ^ rotr(a, 22)) + ((a & b) ^ (a & c) ^ (b & c));
        h = g;
        g = f;
        f = e;
        e = d + t1;
        d = c;
        c = b;
        b = a;
        a = t1 + t2;
    }
    mH[0] += a; mH[1] += b; mH[2] += c; mH[3] += d; mH[4] += e; mH[5] += f; mH[6] += g; mH[7] += h;
}

void Sha256::update(const void* data, std::size_t bytes)
{
    const auto* p = static_cast<const unsigned char*>(data);
    mTotal += bytes;
    while (bytes > 0) {
        const std::size_t n = std::min<std::size_t>(64 - mBufLen, bytes);
        std::memcpy(mBuf + mBufLen, p, n);
        mBufLen += n;
        p += n;
        bytes -= n;
        if (mBufLen == 64) {
            block(mBuf);
            mBufLen = 0;
        }
    }
}

std::string Sha256::hex()
{
    const uint64_t bits = mTotal * 8;
    const unsigned char pad = 0x80, zero = 0;
    update(&pad, 1);
    while (mBufLen != 56) update(&zero, 1);
    unsigned char len[8];
    for (int i = 0; i < 8; ++i) len[i] = static_cast<unsigned char>(bits >> (56 - 8 * i));
    update(len, 8);
    static const char* digits = "0123456789abcdef";
    std::string out;
    for (const uint32_t h : mH)
        for (int s = 28; s >= 0; s -= 4) out.push_back(digits[(h >> s) & 15]);
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

// Mutants of a .vdb file for the robustness tests: byte flips, truncations and oversized length
// words (huge, negative, or a little off: the lies that made OpenVDB 10 overrun a leaf buffer).
#pragma once

#include <gtest/gtest.h>

#include <lic/util/Error.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <string>
#include <vector>

namespace vdb_mutants {

/// The whole file at `path` ("" if it cannot be read).
inline std::string readFile(const std::filesystem::path& path)
{
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

/// Writes `bytes` to `path`, replacing it.
inline void writeFile(const std::filesystem::path& path, const std::string& bytes)
{
    std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
}

/// The message of the lic::InputError that `fn` throws; a test failure (and "") if it throws none.
inline std::string inputErrorOf(const std::function<void()>& fn)
{
    try {
        fn();
    } catch (const lic::InputError& e) {
        return e.what();
    }
    ADD_FAILURE() << "expected lic::InputError, nothing was thrown";
    return {};
}

/// The kinds of mutation, for reporting.
inline const char* kindName(int kind)
{
    static const char* names[] = {"byte flips", "truncation", "huge 4-byte word", "huge 8-byte word", "size off by some"};
    return names[kind];
}
inline constexpr int kKinds = 5;

/// Offsets of little-endian words in `bytes` whose value looks like a size or count (1 .. 2^20):
/// where lying sizes hurt most.
inline std::vector<std::size_t> sizeLikeWords(const std::string& bytes, std::size_t width)
{
    std::vector<std::size_t> at;
    for (std::size_t i = 0; i + width <= bytes.size(); ++i) {
        uint64_t v = 0;
        std::memcpy(&v, bytes.data() + i, width);
        if (v >= 1 && v <= (1u << 20)) at.push_back(i);
    }
    return at;
}

/// Offset of the first blosc header in `bytes` that says it holds `nbytes` bytes, or npos: the
/// header follows the int64 compressed-size word OpenVDB stores before each compressed buffer.
inline std::size_t findBloscHeader(const std::string& bytes, uint32_t nbytes)
{
    for (std::size_t i = 8; i + 16 <= bytes.size(); ++i) {
        uint32_t n = 0, cbytes = 0;
        int64_t stored = 0;
        std::memcpy(&n, &bytes[i + 4], 4);
        std::memcpy(&cbytes, &bytes[i + 12], 4);
        std::memcpy(&stored, &bytes[i - 8], 8);
        if (bytes[i] == 2 && n == nbytes && stored == int64_t(cbytes)) return i;
    }
    return std::string::npos;
}

/// One mutant of `bytes` of the given kind (0 … kKinds-1), drawn from `rng`.
inline std::string mutate(const std::string& bytes, int kind, std::mt19937_64& rng)
{
    std::string m = bytes;
    if (m.empty()) return m;
    const auto pos = [&](std::size_t width) {
        return std::uniform_int_distribution<std::size_t>(0, m.size() > width ? m.size() - width : 0)(rng);
    };
    switch (kind) {
    case 0: { // 1 to 4 random bytes replaced
        const int n = std::uniform_int_distribution<int>(1, 4)(rng);
        for (int i = 0; i < n; ++i) m[pos(1)] = char(rng());
        break;
    }
    case 1: // cut short
        m.resize(pos(1));
        break;
    case 2: { // a huge or negative 4-byte word, often where a size was
        static const uint32_t values[] = {0xFFFFFFFFu, 0x7FFFFFFFu, 0x80000000u, 0x10000000u, 0xFFFFFFF0u, 1u << 24};
        const auto words = sizeLikeWords(m, 4);
        const std::size_t at = (!words.empty() && rng() % 2) ? words[rng() % words.size()] : pos(4);
        const uint32_t v = values[rng() % (sizeof(values) / sizeof(values[0]))];
        std::memcpy(&m[at], &v, std::min<std::size_t>(4, m.size() - at));
        break;
    }
    case 3: { // a huge or negative 8-byte word
        static const int64_t values[] = {INT64_MAX, INT64_MIN, -1, int64_t(1) << 40, int64_t(1) << 32, -(int64_t(1) << 31)};
        const auto words = sizeLikeWords(m, 8);
        const std::size_t at = (!words.empty() && rng() % 2) ? words[rng() % words.size()] : pos(8);
        const int64_t v = values[rng() % (sizeof(values) / sizeof(values[0]))];
        std::memcpy(&m[at], &v, std::min<std::size_t>(8, m.size() - at));
        break;
    }
    default: { // a size-like word made a little larger or smaller (e.g. 6144 → 8182)
        const std::size_t width = (rng() % 2) ? 4 : 8;
        const auto words = sizeLikeWords(m, width);
        if (words.empty()) break;
        const std::size_t at = words[rng() % words.size()];
        uint64_t v = 0;
        std::memcpy(&v, &m[at], width);
        const int64_t delta = std::uniform_int_distribution<int64_t>(-4096, 4096)(rng);
        v = uint64_t(int64_t(v) + (delta == 0 ? 2038 : delta));
        std::memcpy(&m[at], &v, width);
        break;
    }
    }
    return m;
}

} // namespace vdb_mutants

// Helpers shared by the dense-format readers (npy, vti, legacy vtk, raw). Internal.
#pragma once

#include "vdbexport/io/FieldInput.h"

#include "Quote.h"

#include <lic/util/Error.h>

#include <bit>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

namespace vdbexport::detail {

[[noreturn]] inline void inputError(const std::string& source, const std::string& what)
{
    throw lic::InputError(q(source) + ": " + what);
}

/// Element types the readers convert to float.
enum class Elem { F32, F64, I8, U8, I16, U16, I32, U32, I64, U64 };

inline std::size_t elemSize(Elem e)
{
    switch (e) {
    case Elem::I8: case Elem::U8: return 1;
    case Elem::I16: case Elem::U16: return 2;
    case Elem::F32: case Elem::I32: case Elem::U32: return 4;
    default: return 8;
    }
}

/// Value `index` of an array of `e` starting at `p`, byte-swapped if `swap`, as float.
inline float loadElem(const unsigned char* p, Elem e, bool swap, std::size_t index)
{
    const std::size_t n = elemSize(e);
    unsigned char b[8];
    std::memcpy(b, p + index * n, n);
    if (swap)
        for (std::size_t i = 0; i < n / 2; ++i) std::swap(b[i], b[n - 1 - i]);
    switch (e) {
    case Elem::F32: { float v; std::memcpy(&v, b, 4); return v; }
    case Elem::F64: { double v; std::memcpy(&v, b, 8); return float(v); }
    case Elem::I8: { int8_t v; std::memcpy(&v, b, 1); return float(v); }
    case Elem::U8: return float(b[0]);
    case Elem::I16: { int16_t v; std::memcpy(&v, b, 2); return float(v); }
    case Elem::U16: { uint16_t v; std::memcpy(&v, b, 2); return float(v); }
    case Elem::I32: { int32_t v; std::memcpy(&v, b, 4); return float(v); }
    case Elem::U32: { uint32_t v; std::memcpy(&v, b, 4); return float(v); }
    case Elem::I64: { int64_t v; std::memcpy(&v, b, 8); return float(v); }
    case Elem::U64: { uint64_t v; std::memcpy(&v, b, 8); return float(v); }
    }
    return 0.0f;
}

inline bool hostIsLittle() { return std::endian::native == std::endian::little; }

/// Refuse dimensions that are non-positive or whose product exceeds kMaxDenseVoxels, before
/// anything is allocated.
inline void checkDims(const std::array<std::int64_t, 3>& d, const std::string& source)
{
    for (int a = 0; a < 3; ++a) {
        if (d[a] < 1)
            inputError(source, "dimension " + std::string(1, "XYZ"[a]) + " is " + std::to_string(d[a])
                                   + "; expected at least 1 voxel on every axis");
        if (d[a] > std::int64_t(kMaxDenseVoxels))
            inputError(source, "declared dimensions " + std::to_string(d[0]) + " x " + std::to_string(d[1])
                                   + " x " + std::to_string(d[2]) + " are too large (limit "
                                   + std::to_string(kMaxDenseVoxels) + " voxels)");
    }
    // Each factor is <= 2^28, so the first product fits in 64 bits; divide for the second.
    const std::uint64_t xy = std::uint64_t(d[0]) * std::uint64_t(d[1]);
    if (xy > kMaxDenseVoxels / std::uint64_t(d[2]))
        inputError(source, "declared dimensions " + std::to_string(d[0]) + " x " + std::to_string(d[1]) + " x "
                               + std::to_string(d[2]) + " are too large (limit " + std::to_string(kMaxDenseVoxels)
                               + " voxels); refusing to allocate");
}

/// A parsed .npy header and where its data starts (inside the bytes given to parseNpyArray).
struct NpyArray
{
    std::vector<std::int64_t> shape;
    Elem elem = Elem::F32;
    std::string descr;                ///< the header's dtype text ('<f4', ...)
    bool bigEndian = false, fortran = false;
    const unsigned char* data = nullptr;
    std::size_t available = 0;        ///< bytes after the header
};

/// Parse a .npy file's header (versions 1.0, 2.0, 3.0).
/// @throw lic::InputError naming `source` for a bad magic, version, header, dtype or shape.
NpyArray parseNpyArray(std::string_view bytes, const std::string& source);

} // namespace vdbexport::detail

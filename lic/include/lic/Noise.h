// Dense white-noise input texture: one value in [0,1) per output voxel from a hash of
// (seed, voxel), so any part of the volume can be regenerated independently of the rest.
#pragma once

#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdint>

namespace lic {

/// 64-bit avalanche hash of a seed and three integer coordinates (splitmix64 finaliser over a
/// multiply–xor combination). Pure function: the same inputs give the same bits everywhere.
inline std::uint64_t hashCoord(std::uint64_t seed, int i, int j, int k)
{
    std::uint64_t h = seed * 0x9E3779B97F4A7C15ull;
    h ^= std::uint64_t(std::uint32_t(i)) * 0xBF58476D1CE4E5B9ull;
    h = (h ^ (h >> 31)) * 0x94D049BB133111EBull;
    h ^= std::uint64_t(std::uint32_t(j)) * 0xD6E8FEB86659FD93ull;
    h = (h ^ (h >> 29)) * 0xBF58476D1CE4E5B9ull;
    h ^= std::uint64_t(std::uint32_t(k)) * 0x9E3779B97F4A7C15ull;
    h = (h ^ (h >> 30)) * 0xBF58476D1CE4E5B9ull;
    h = (h ^ (h >> 27)) * 0x94D049BB133111EBull;
    return h ^ (h >> 31);
}

/// White noise value in [0, 1) of output voxel (i, j, k) (24 bits of the hash).
inline float whiteNoise(std::uint64_t seed, int i, int j, int k)
{
    return float(hashCoord(seed, i, j, k) >> 40) * (1.0f / 16777216.0f);
}

/// The noise input texture: per-voxel white noise, reconstructed trilinearly between voxel
/// centres so that streamline samples between voxels see a continuous texture.
/// Positions are OUTPUT index space. One channel.
class NoiseTexture
{
public:
    static constexpr int kChannels = 1;

    explicit NoiseTexture(std::uint64_t seed) : mSeed(seed) {}

    std::uint64_t seed() const { return mSeed; }

    /// Value at voxel (i, j, k): what `--write-input` writes.
    float voxel(const openvdb::Coord& ijk) const { return whiteNoise(mSeed, ijk[0], ijk[1], ijk[2]); }

    /// Trilinear value at a continuous output-index position.
    void sample(const openvdb::Vec3d& p, float* out) const { sampleGradient(p, out, nullptr); }

    /// Trilinear value and, if `grad` is non-null, its gradient (d/di, d/dj, d/dk) per channel.
    void sampleGradient(const openvdb::Vec3d& p, float* out, float* grad) const
    {
        const double fx0 = std::floor(p[0]), fy0 = std::floor(p[1]), fz0 = std::floor(p[2]);
        const int i = int(fx0), j = int(fy0), k = int(fz0);
        const float fx = float(p[0] - fx0), fy = float(p[1] - fy0), fz = float(p[2] - fz0);
        float n[2][2][2];
        for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b)
                for (int c = 0; c < 2; ++c) n[a][b][c] = whiteNoise(mSeed, i + a, j + b, k + c);
        auto lerp = [](float u, float v, float t) { return u + (v - u) * t; };
        const float c00 = lerp(n[0][0][0], n[0][0][1], fz), c01 = lerp(n[0][1][0], n[0][1][1], fz);
        const float c10 = lerp(n[1][0][0], n[1][0][1], fz), c11 = lerp(n[1][1][0], n[1][1][1], fz);
        const float c0 = lerp(c00, c01, fy), c1 = lerp(c10, c11, fy);
        out[0] = lerp(c0, c1, fx);
        if (grad) {
            grad[0] = c1 - c0;
            grad[1] = lerp(c01 - c00, c11 - c10, fx);
            const float d00 = n[0][0][1] - n[0][0][0], d01 = n[0][1][1] - n[0][1][0];
            const float d10 = n[1][0][1] - n[1][0][0], d11 = n[1][1][1] - n[1][1][0];
            grad[2] = lerp(lerp(d00, d01, fy), lerp(d10, d11, fy), fx);
        }
    }

private:
    std::uint64_t mSeed;
};

/// A constant texture (every channel = `value`): LIC of it must return `value` everywhere.
class ConstantTexture
{
public:
    static constexpr int kChannels = 1;
    explicit ConstantTexture(float value) : mValue(value) {}
    void sample(const openvdb::Vec3d&, float* out) const { out[0] = mValue; }
    void sampleGradient(const openvdb::Vec3d&, float* out, float* grad) const
    {
        out[0] = mValue;
        if (grad) grad[0] = grad[1] = grad[2] = 0.0f;
    }

private:
    float mValue;
};

} // namespace lic

// Dense white-noise input texture: one value in [0,1) per output voxel from a hash of
// (seed, voxel), so any part of the volume can be regenerated independently of the rest.
#pragma once

#include "lic/field/Bricks.h"
#include "lic/util/Names.h"

#include <openvdb/openvdb.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <functional>
#include <span>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

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

/// How the per-voxel white noise is reconstructed between voxel centres.
enum class NoiseFilter {
    None,    ///< trilinear interpolation of the raw per-voxel values
    Binomial ///< each voxel's value low-passed by the separable 3³ binomial [¼ ½ ¼] first
};
/// @throw lic::InputError for names other than "binomial" and "none".
NoiseFilter noiseFilterFromString(const std::string&);
/// The filters' names (a recipe's allowed values).
inline constexpr EnumName<NoiseFilter> kFilterNames[] = {{NoiseFilter::Binomial, "binomial"}, {NoiseFilter::None, "none"}};
inline std::span<const EnumName<NoiseFilter>> noiseFilterNames() { return kFilterNames; }

/// The dense noise input texture. Each output voxel has a white-noise value in [0, 1) from a hash
/// of (seed, voxel); with NoiseFilter::Binomial the texture value of a voxel is the [¼ ½ ¼]³
/// weighted mean of its 3³ neighbourhood (band-limiting the noise to what the output grid can
/// represent, so streamlines are anti-aliased and fast-LIC's off-centre deposits stay accurate).
/// Between voxel centres the texture is trilinear. Values are precomputed over a box (the output
/// bounding box plus a margin); positions beyond it clamp to its edge. Any sub-box gives the same
/// values whatever box it is computed in. Positions are OUTPUT index space; one channel.
class NoiseTexture
{
public:
    static constexpr int kChannels = 1;

    /// @param box output voxels to precompute (inclusive); ~4 bytes per voxel of box + margin.
    NoiseTexture(std::uint64_t seed, const openvdb::CoordBBox& box,
                 NoiseFilter filter = NoiseFilter::Binomial);
    /// An empty texture, to be filled by assign().
    NoiseTexture() : mSeed(0), mFilter(NoiseFilter::Binomial), mLo(0), mDim{0, 0, 0}, mBricks{0, 0, 0} {}

    /// The white-noise value of a voxel before filtering; by default whiteNoise(seed, voxel). An
    /// unsteady bake supplies the noise carried along the flow (texture/Advection.h). Must be thread-safe.
    using RawNoise = std::function<float(const openvdb::Coord&)>;

    /// Recompute for another box, reusing the storage. `parallel` = false for a caller that is
    /// itself one task of a parallel loop (a brick). `raw`: the per-voxel white noise, if not
    /// whiteNoise(seed, voxel).
    void assign(std::uint64_t seed, const openvdb::CoordBBox& box, NoiseFilter filter, bool parallel = true,
                const RawNoise* raw = nullptr);
    /// The box the values were computed for (the constructor's box).
    const openvdb::CoordBBox& box() const { return mBox; }
    bool built() const { return !mData.empty(); }

    std::uint64_t seed() const { return mSeed; }
    NoiseFilter filter() const { return mFilter; }

    /// Texture value at voxel (i, j, k): what `--write-input` writes.
    float voxel(const openvdb::Coord& ijk) const { return at(ijk[0], ijk[1], ijk[2]); }

    /// Multiply every stored voxel value by weight(voxel) (a region-of-interest pre-mask), in
    /// parallel; `weight` must be thread-safe and deterministic.
    template<typename F>
    void multiply(const F& weight, bool parallel = true)
    {
        auto slab = [&](int i) {
            for (int j = 0; j < mDim[1]; ++j)
                for (int k = 0; k < mDim[2]; ++k)
                    mData[offset(i, j, k)] *= float(weight(mLo + openvdb::Coord(i, j, k)));
        };
        if (parallel) tbb::parallel_for(0, mDim[0], slab);
        else for (int i = 0; i < mDim[0]; ++i) slab(i);
    }

    /// Trilinear value at a continuous output-index position.
    void sample(const openvdb::Vec3d& p, float* out) const { sampleGradient(p, out, nullptr); }

    /// Trilinear value and, if `grad` is non-null, its gradient (d/di, d/dj, d/dk).
    [[gnu::always_inline]] void sampleGradient(const openvdb::Vec3d& p, float* out, float* grad) const
    {
        const int xi = detail::floorIndex(p[0]), yi = detail::floorIndex(p[1]), zi = detail::floorIndex(p[2]);
        const double fx0 = double(xi), fy0 = double(yi), fz0 = double(zi);
        const int i = xi - mLo[0], j = yi - mLo[1], k = zi - mLo[2];
        const float fx = float(p[0] - fx0), fy = float(p[1] - fy0), fz = float(p[2] - fz0);
        // The bricked offset is a sum of per-axis terms, so the eight corners cost six clamps.
        const std::size_t X0 = axisX(i), X1 = axisX(i + 1), Y0 = axisY(j), Y1 = axisY(j + 1);
        const std::size_t Z0 = axisZ(k), Z1 = axisZ(k + 1);
        const float* d = mData.data();
        float n[2][2][2] = {{{d[X0 + Y0 + Z0], d[X0 + Y0 + Z1]}, {d[X0 + Y1 + Z0], d[X0 + Y1 + Z1]}},
                            {{d[X1 + Y0 + Z0], d[X1 + Y0 + Z1]}, {d[X1 + Y1 + Z0], d[X1 + Y1 + Z1]}}};
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
    float at(int i, int j, int k) const
    {
        i = std::clamp(i - mLo[0], 0, mDim[0] - 1);
        j = std::clamp(j - mLo[1], 0, mDim[1] - 1);
        k = std::clamp(k - mLo[2], 0, mDim[2] - 1);
        return mData[offset(i, j, k)];
    }
    // Per-axis parts of offset() for box-relative indices, clamped to the box.
    std::size_t axisX(int i) const
    {
        i = std::clamp(i, 0, mDim[0] - 1);
        return std::size_t(i >> 3) * std::size_t(mBricks[1]) * std::size_t(mBricks[2]) * 512 + std::size_t((i & 7) << 6);
    }
    std::size_t axisY(int j) const
    {
        j = std::clamp(j, 0, mDim[1] - 1);
        return std::size_t(j >> 3) * std::size_t(mBricks[2]) * 512 + std::size_t((j & 7) << 3);
    }
    std::size_t axisZ(int k) const
    {
        k = std::clamp(k, 0, mDim[2] - 1);
        return std::size_t(k >> 3) * 512 + std::size_t(k & 7);
    }
    /// Storage is in 8³ bricks so the 8 corners of a lookup usually share a brick (cache lines).
    std::size_t offset(int i, int j, int k) const
    {
        const std::size_t brick =
            (std::size_t(i >> 3) * std::size_t(mBricks[1]) + std::size_t(j >> 3)) * std::size_t(mBricks[2]) +
            std::size_t(k >> 3);
        return brick * 512 + std::size_t(((i & 7) << 6) | ((j & 7) << 3) | (k & 7));
    }

    std::uint64_t mSeed;
    NoiseFilter mFilter;
    openvdb::CoordBBox mBox;
    openvdb::Coord mLo;
    int mDim[3];
    int mBricks[3];
    std::vector<float> mData;
    std::vector<float> mRaw, mPass; // filter scratch, kept for reuse
};

/// The noise of each brick and its ghost margin, made on the worker thread that convolves the
/// brick (storage reused per thread): a bake never holds the noise of the whole volume. Values
/// are those of one NoiseTexture over everything (they depend only on seed and voxel).
/// Satisfies convolveBricks()' textureFor.
class NoiseBrickSource
{
public:
    /// `premask(texture)`, if given, multiplies a brick's noise by a region-of-interest weight
    /// (serially: it runs inside a brick's task).
    using Premask = std::function<void(NoiseTexture&)>;
    NoiseBrickSource(std::uint64_t seed, NoiseFilter filter, int margin, Premask premask = {},
                     NoiseTexture::RawNoise raw = {})
        : mSeed(seed), mFilter(filter), mMargin(margin), mPremask(std::move(premask)), mRaw(std::move(raw))
    {
    }
    /// Make each brick's noise only where a lookup can land: `reach` (output voxels) holds every
    /// voxel a streamline's samples can interpolate between (the field's extent). A brick by the
    /// domain's edge then skips the part of its margin outside the field (at length 40 on a 128³
    /// volume the margin is most of the texture). The values are the same: a voxel's noise does not
    /// depend on the box, and no lookup inside the reach is clamped differently.
    void clipTo(const openvdb::CoordBBox& reach) { mReach = reach; }

    /// The noise over `brick.box` grown by the margin (within the reach, if clipped); the same
    /// brick asked for twice in a row on one thread is made once.
    const NoiseTexture& operator()(const Brick& brick)
    {
        openvdb::CoordBBox box = brick.box.expandBy(mMargin);
        if (!mReach.empty()) box.intersect(mReach);
        NoiseTexture& t = mTls.local();
        if (t.built() && t.box() == box) return t;
        t.assign(mSeed, box, mFilter, false, mRaw ? &mRaw : nullptr);
        if (mPremask) mPremask(t);
        return t;
    }

private:
    std::uint64_t mSeed;
    NoiseFilter mFilter;
    int mMargin;
    Premask mPremask;
    NoiseTexture::RawNoise mRaw;
    openvdb::CoordBBox mReach; // empty: no clip
    tbb::enumerable_thread_specific<NoiseTexture> mTls;
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

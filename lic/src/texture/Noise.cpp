#include "lic/texture/Noise.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"

#include <tbb/parallel_for.h>

namespace lic {

NoiseFilter noiseFilterFromString(const std::string& s)
{
    return valueOf<NoiseFilter>(kFilterNames, s, "noise filter");
}

NoiseTexture::NoiseTexture(std::uint64_t seed, const openvdb::CoordBBox& box, NoiseFilter filter)
    : NoiseTexture()
{
    assign(seed, box, filter, true);
}

void NoiseTexture::assign(std::uint64_t seed, const openvdb::CoordBBox& box, NoiseFilter filter, bool parallel,
                          const RawNoise* rawNoise)
{
    auto white = [&](int i, int j, int k) {
        return rawNoise ? (*rawNoise)(openvdb::Coord(i, j, k)) : whiteNoise(seed, i, j, k);
    };
    mSeed = seed;
    mFilter = filter;
    mBox = box;
    // One voxel of margin for trilinear lookups past the box edge.
    mLo = box.min() - openvdb::Coord(1);
    const openvdb::Coord hi = box.max() + openvdb::Coord(1);
    for (int a = 0; a < 3; ++a) mDim[a] = hi[a] - mLo[a] + 1;
    const std::size_t nx = std::size_t(mDim[0]), ny = std::size_t(mDim[1]), nz = std::size_t(mDim[2]);
    for (int a = 0; a < 3; ++a) mBricks[a] = (mDim[a] + 7) / 8;
    mData.assign(std::size_t(mBricks[0]) * mBricks[1] * mBricks[2] * 512, 0.0f);
    auto index = [&](std::size_t i, std::size_t j, std::size_t k) { return offset(int(i), int(j), int(k)); };
    auto forEach = [parallel](std::size_t n, const auto& fn) {
        if (parallel) tbb::parallel_for(std::size_t(0), n, fn);
        else for (std::size_t i = 0; i < n; ++i) fn(i);
    };

    if (filter == NoiseFilter::None) {
        forEach(nx, [&](std::size_t i) {
            for (std::size_t j = 0; j < ny; ++j)
                for (std::size_t k = 0; k < nz; ++k)
                    mData[index(i, j, k)] = white(mLo[0] + int(i), mLo[1] + int(j), mLo[2] + int(k));
        });
        return;
    }
    // Separable [¼ ½ ¼]: raw noise on the box grown by one more voxel, then one pass per axis.
    const std::size_t rx = nx + 2, ry = ny + 2, rz = nz + 2;
    std::vector<float>& raw = mRaw;
    std::vector<float>& pass = mPass;
    raw.resize(rx * ry * rz);
    pass.resize(rx * ry * rz);
    auto rindex = [&](std::size_t i, std::size_t j, std::size_t k) { return (i * ry + j) * rz + k; };
    forEach(rx, [&](std::size_t i) {
        for (std::size_t j = 0; j < ry; ++j)
            for (std::size_t k = 0; k < rz; ++k)
                raw[rindex(i, j, k)] =
                    white(mLo[0] - 1 + int(i), mLo[1] - 1 + int(j), mLo[2] - 1 + int(k));
    });
    // z pass (raw → pass), y pass (pass → raw), x pass (raw → mData); edges use what exists.
    forEach(rx, [&](std::size_t i) {
        for (std::size_t j = 0; j < ry; ++j)
            for (std::size_t k = 1; k + 1 < rz; ++k)
                pass[rindex(i, j, k)] = 0.25f * raw[rindex(i, j, k - 1)] + 0.5f * raw[rindex(i, j, k)] +
                                        0.25f * raw[rindex(i, j, k + 1)];
    });
    forEach(rx, [&](std::size_t i) {
        for (std::size_t j = 1; j + 1 < ry; ++j)
            for (std::size_t k = 1; k + 1 < rz; ++k)
                raw[rindex(i, j, k)] = 0.25f * pass[rindex(i, j - 1, k)] + 0.5f * pass[rindex(i, j, k)] +
                                       0.25f * pass[rindex(i, j + 1, k)];
    });
    forEach(nx, [&](std::size_t i) {
        for (std::size_t j = 0; j < ny; ++j)
            for (std::size_t k = 0; k < nz; ++k)
                mData[index(i, j, k)] = 0.25f * raw[rindex(i, j + 1, k + 1)] +
                                        0.5f * raw[rindex(i + 1, j + 1, k + 1)] +
                                        0.25f * raw[rindex(i + 2, j + 1, k + 1)];
    });
    if (parallel) { // one texture for a whole volume: no second brick will reuse the scratch
        std::vector<float>().swap(mRaw);
        std::vector<float>().swap(mPass);
    }
}

} // namespace lic

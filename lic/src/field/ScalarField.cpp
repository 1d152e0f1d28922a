#include "lic/field/ScalarField.h"

#include "lic/util/Error.h"
#include "lic/util/Parallel.h"
#include "lic/field/Region.h"
#include "lic/field/Scalars.h"

#include <openvdb/tools/Dense.h>

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <bit>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

namespace lic {

namespace {
const char* const kWholeBoxMin = "licvdb_whole_active_bbox_min";
const char* const kWholeBoxMax = "licvdb_whole_active_bbox_max";
const char* const kPartBoxMin = "licvdb_part_bbox_min";
const char* const kPartBoxMax = "licvdb_part_bbox_max";

std::optional<openvdb::CoordBBox> boxMeta(const openvdb::GridBase& grid, const char* lo, const char* hi)
{
    const auto a = grid.getMetadata<openvdb::Vec3IMetadata>(lo);
    const auto b = grid.getMetadata<openvdb::Vec3IMetadata>(hi);
    if (a && b) return openvdb::CoordBBox(openvdb::Coord(a->value()), openvdb::Coord(b->value()));
    return std::nullopt;
}
} // namespace

openvdb::CoordBBox activeBoxOf(const openvdb::GridBase& grid)
{
    if (auto b = boxMeta(grid, kWholeBoxMin, kWholeBoxMax)) return *b;
    return grid.evalActiveVoxelBoundingBox();
}

openvdb::CoordBBox partBoxOf(const openvdb::GridBase& grid)
{
    if (auto b = boxMeta(grid, kPartBoxMin, kPartBoxMax)) return *b;
    return activeBoxOf(grid);
}

bool isPart(const openvdb::GridBase& grid) { return boxMeta(grid, kWholeBoxMin, kWholeBoxMax).has_value(); }

void setPartOf(openvdb::GridBase& grid, const openvdb::CoordBBox& whole, const openvdb::CoordBBox& part)
{
    grid.insertMeta(kWholeBoxMin, openvdb::Vec3IMetadata(whole.min().asVec3i()));
    grid.insertMeta(kWholeBoxMax, openvdb::Vec3IMetadata(whole.max().asVec3i()));
    grid.insertMeta(kPartBoxMin, openvdb::Vec3IMetadata(part.min().asVec3i()));
    grid.insertMeta(kPartBoxMax, openvdb::Vec3IMetadata(part.max().asVec3i()));
}

openvdb::FloatGrid::ConstPtr ScalarSet::get(const std::string& name)
{
    const std::lock_guard lock(mMutex);
    return resolve(name);
}

openvdb::FloatGrid::ConstPtr ScalarSet::resolve(const std::string& name)
{
    if (auto it = mCache.find(name); it != mCache.end()) return it->second;
    static const std::string kGradient = "-gradient";
    static const std::string kAbs = "-abs";
    const bool part = isPart(mVelocity);
    openvdb::FloatGrid::ConstPtr g;
    if (name.size() > kAbs.size() && name.ends_with(kAbs)) {
        // |NAME|: same topology (and part boxes) as NAME, every active value made non-negative.
        const auto base = resolve(name.substr(0, name.size() - kAbs.size()));
        auto mag = base->deepCopy();
        mag->setName(name);
        for (auto it = mag->beginValueOn(); it; ++it) it.setValue(std::abs(*it));
        g = mag;
    } else if (name.size() > kGradient.size() && name.ends_with(kGradient)) {
        const auto base = resolve(name.substr(0, name.size() - kGradient.size()));
        auto grad = gradientMagnitude(*base, name);
        // Same active topology as its base: a part's boxes are the base's.
        if (isPart(*base)) setPartOf(*grad, activeBoxOf(*base), partBoxOf(*base));
        g = grad;
    } else {
        g = resolveScalar(mVelocity, mFile, name);
        if (part && !isPart(*g)) {
            // Derived from a part of the velocity (file scalars carry their own boxes): the
            // velocity's topology, so its boxes.
            auto derived = openvdb::ConstPtrCast<openvdb::FloatGrid>(g);
            setPartOf(*derived, activeBoxOf(mVelocity), partBoxOf(mVelocity));
        }
    }
    return mCache[name] = g;
}

ScalarField::ScalarField(openvdb::FloatGrid::ConstPtr grid)
    : mGrid(std::move(grid))
{
    const bool part = isPart(*mGrid);
    const openvdb::CoordBBox bb = part ? activeBoxOf(*mGrid) : mGrid->evalActiveVoxelBoundingBox();
    if (bb.empty()) throw InputError("scalar grid \"" + mGrid->getName() + "\" has no active voxels");
    openvdb::CoordBBox held = bb; // the dense copy: the active box, or the part of it held here
    if (part) {
        held.intersect(partBoxOf(*mGrid));
        if (held.empty()) held = openvdb::CoordBBox(bb.min(), bb.min());
    }
    const openvdb::Coord dim = held.dim();
    if (double(dim[0]) * dim[1] * dim[2] > double(1u << 28)) {
        throw InputError("scalar grid \"" + mGrid->getName() + "\" has an active bounding box of more than 2^28 "
                              "voxels; crop or resample the field");
    }
    mWorldToIndex = AffineMap(mGrid->transform()).worldToIndex;
    for (int a = 0; a < 3; ++a) {
        mLo[a] = bb.min()[a];
        mHi[a] = bb.max()[a];
        mOff[a] = held.min()[a] - bb.min()[a];
        mDim[a] = dim[a];
    }
    mStride[0] = std::size_t(dim[1]) * std::size_t(dim[2]);
    mStride[1] = std::size_t(dim[2]);
    mStride[2] = 1;
    // Straight into the held array (copyToDense writes every voxel of the box).
    mData.resize(std::size_t(dim[0]) * std::size_t(dim[1]) * std::size_t(dim[2]));
    openvdb::tools::Dense<float, openvdb::tools::LayoutZYX> dense(held, mData.data());
    openvdb::tools::copyToDense(*mGrid, dense);
}

namespace {

/// Whether p·M (AffineMap::apply) gives each component from that axis alone, bit for bit: the
/// linear part diagonal with positive entries. Then the off-diagonal terms are ±0 and the diagonal
/// term of an integral (or non-negative-zero) input is never −0, so adding them changes nothing.
bool axisAligned(const openvdb::Mat4d& m)
{
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (i == j ? !(m[i][j] > 0.0 && std::isfinite(m[i][j])) : m[i][j] != 0.0) return false;
    return std::isfinite(m[3][0]) && std::isfinite(m[3][1]) && std::isfinite(m[3][2]);
}

} // namespace

ScalarField::BlockSampler::BlockSampler(const ScalarField& scalar, const OutputDomain& domain)
    : mScalar(scalar)
    , mDomain(domain)
    , mSeparable(axisAligned(domain.map().indexToWorld) && axisAligned(scalar.mWorldToIndex))
{
}

float ScalarField::BlockSampler::general(openvdb::Index off) const
{
    const openvdb::Coord ijk = mOrigin + openvdb::Coord(int(off >> 6), int((off >> 3) & 7u), int(off & 7u));
    return mScalar.at(mDomain.worldOf(ijk));
}

void ScalarField::BlockSampler::setBlock(const openvdb::Coord& origin)
{
    mOrigin = origin;
    if (!mSeparable) return;
    const openvdb::Mat4d& out = mDomain.map().indexToWorld;
    const openvdb::Mat4d& in = mScalar.mWorldToIndex;
    for (int a = 0; a < 3; ++a)
        for (int c = 0; c < OutputDomain::kBlockDim; ++c) {
            // AffineMap::apply's component a without its zero terms (see axisAligned).
            const double world = double(origin[a] + c) * out[a][a] + out[3][a];
            mAxis[a][c] = mScalar.axis(a, world * in[a][a] + in[3][a]);
        }
}

namespace {

/// Order-preserving key of a float: larger floats get larger keys.
std::uint32_t orderKey(float v)
{
    const std::uint32_t b = std::bit_cast<std::uint32_t>(v);
    return (b & 0x80000000u) ? ~b : (b | 0x80000000u);
}
float fromKey(std::uint32_t k) { return std::bit_cast<float>((k & 0x80000000u) ? (k & 0x7fffffffu) : ~k); }

using Histogram = std::vector<std::uint64_t>;

/// A histogram of `bins` bins over the finite samples at the active output voxels:
/// `add(key, h, i)` counts the sample's order key into h, i numbering the voxels (blocks in
/// order, each block's voxels in mask order, from `first[block]`); `sample(i)` says whether voxel
/// i is sampled at all.
template<typename Sample, typename Add>
Histogram histogram(const ScalarField& scalar, const OutputDomain& domain, int threads, std::size_t bins,
                    const std::vector<std::uint32_t>* blocks, const std::vector<std::size_t>& first,
                    const HistogramReduce& reduce, Sample sample, Add add)
{
    tbb::combinable<Histogram> parts([bins] { return Histogram(bins, 0); });
    const std::size_t count = blocks ? blocks->size() : domain.blockCount();
    {
        const ThreadLimit threadLimit(threads);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count), [&](const auto& r) {
            Histogram& h = parts.local();
            ScalarField::BlockSampler at(scalar, domain);
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                const std::size_t b = blocks ? (*blocks)[i] : i;
                std::size_t voxel = first[i];
                const auto& mask = domain.blockMask(b);
                at.setBlock(domain.blockOrigin(b));
                for (auto on = mask.beginOn(); on; ++on, ++voxel) {
                    if (!sample(voxel)) continue;
                    const float v = at.at(on.pos());
                    if (std::isfinite(v)) add(orderKey(v), h, voxel);
                }
            }
        });
    }
    Histogram all(bins, 0);
    parts.combine_each([&](const Histogram& h) {
        for (std::size_t i = 0; i < all.size(); ++i) all[i] += h[i]; // integer sums: any order
    });
    if (reduce) reduce(all); // over the processes: integer sums again
    return all;
}

/// The bin holding rank `k` of `h` and the count below that bin.
std::pair<int, std::uint64_t> binOfRank(const Histogram& h, std::uint64_t k)
{
    std::uint64_t below = 0;
    for (std::size_t i = 0; i < h.size(); ++i) {
        if (k < below + h[i]) return {int(i), below};
        below += h[i];
    }
    return {int(h.size()) - 1, below};
}

} // namespace

std::array<double, 2> autoRange(const ScalarField& scalar, const OutputDomain& domain, int threads)
{
    return autoRange(scalar, domain, threads, nullptr, {});
}

std::array<double, 2> autoRange(const ScalarField& scalar, const OutputDomain& domain, int threads,
                                const std::vector<std::uint32_t>* blocks, const HistogramReduce& reduce)
{
    constexpr std::size_t kBins = 65536;
    // Where each block's voxels start in a per-voxel numbering. While the volume is small enough
    // (2 bytes a voxel, at most 64 MiB), the first pass keeps each voxel's high key, so that the
    // second samples only the voxels of the two bins that hold the percentiles.
    constexpr std::size_t kKeepLimit = std::size_t(1) << 25;
    const std::size_t count = blocks ? blocks->size() : domain.blockCount();
    std::vector<std::size_t> first(count + 1, 0);
    for (std::size_t i = 0; i < count; ++i)
        first[i + 1] = first[i] + domain.blockMask(blocks ? (*blocks)[i] : i).countOn();
    const bool keep = first[count] <= kKeepLimit;
    // Not zero-filled up front (a serial pass over 2 bytes a voxel): the first pass writes every
    // voxel's entry, in parallel (0 where the value is not finite; the second pass skips those again).
    const std::unique_ptr<std::uint16_t[]> high(keep ? new std::uint16_t[first[count]] : nullptr);
    auto all = [&](std::size_t voxel) {
        if (keep) high[voxel] = 0;
        return true;
    };
    const Histogram coarse = histogram(scalar, domain, threads, kBins, blocks, first, reduce, all,
                                       [&](std::uint32_t key, Histogram& h, std::size_t voxel) {
                                           ++h[key >> 16];
                                           if (keep) high[voxel] = std::uint16_t(key >> 16);
                                       });
    std::uint64_t n = 0;
    for (std::uint64_t c : coarse) n += c;
    if (n == 0) return {0.0, 1.0};
    // Rank of the q-quantile as std::nth_element would pick it: round(q · (n − 1)).
    auto rankOf = [&](double q) { return std::min(n - 1, std::uint64_t(q * double(n - 1) + 0.5)); };
    const std::uint64_t ranks[2] = {rankOf(0.01), rankOf(0.99)};
    // Second pass: the low 16 bits of the keys inside each percentile's coarse bin. (A voxel whose
    // kept high key matches is sampled again; one whose value was not finite is skipped again.)
    const auto [bin0, below0] = binOfRank(coarse, ranks[0]);
    const auto [bin1, below1] = binOfRank(coarse, ranks[1]);
    const std::uint32_t hb[2] = {std::uint32_t(bin0), std::uint32_t(bin1)};
    auto inBins = [&](std::size_t voxel) { return !keep || high[voxel] == hb[0] || high[voxel] == hb[1]; };
    const Histogram fine = histogram(scalar, domain, threads, 2 * kBins, blocks, first, reduce, inBins,
                                     [&hb](std::uint32_t key, Histogram& h, std::size_t) {
                                         for (std::size_t i = 0; i < 2; ++i)
                                             if ((key >> 16) == hb[i]) ++h[i * kBins + (key & 0xffffu)];
                                     });
    const std::uint64_t below[2] = {below0, below1};
    std::array<double, 2> out{};
    for (std::size_t i = 0; i < 2; ++i) {
        const Histogram part(fine.begin() + std::ptrdiff_t(i * kBins), fine.begin() + std::ptrdiff_t((i + 1) * kBins));
        const int lo = binOfRank(part, ranks[i] - below[i]).first;
        out[i] = double(fromKey((hb[i] << 16) | std::uint32_t(lo)));
    }
    if (!(out[1] > out[0])) out[1] = out[0] + 1.0; // constant scalar: everything maps to the low end
    return out;
}

} // namespace lic

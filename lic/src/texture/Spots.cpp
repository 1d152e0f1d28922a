#include "lic/texture/Spots.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"
#include "lic/texture/Noise.h"

#include <algorithm>
#include <array>
#include <numeric>

namespace lic {

using openvdb::Vec3d;

const char* toString(SpotDistribution d) { return nameOf<SpotDistribution>(kDistributionNames, d); }

SpotDistribution spotDistributionFromString(const std::string& s)
{
    return valueOf<SpotDistribution>(kDistributionNames, s, "spot distribution");
}

namespace {

/// Uniform [0, 1) from a hash of (seed, stream, counter): a counter-based generator, so every
/// draw is a pure function of its index.
struct HashRng
{
    std::uint64_t seed;
    int stream;
    std::uint64_t counter = 0;
    double next()
    {
        const std::uint64_t c = counter++;
        const std::uint64_t h = hashCoord(seed, int(std::uint32_t(c)), int(std::uint32_t(c >> 32)), stream);
        return double(h >> 11) * (1.0 / 9007199254740992.0);
    }
};

double uniformAt(std::uint64_t seed, int i, int j, int k, int salt)
{
    return double(hashCoord(seed ^ (0xA5A5A5A5ull * std::uint64_t(salt + 1)), i, j, k) >> 11) *
           (1.0 / 9007199254740992.0);
}

void checkCount(double count)
{
    if (count > double(1 << 26)) {
        throw InputError("spot spacing is too small for this volume: it would place about " +
                         std::to_string(std::uint64_t(count)) + " spots (limit 67 million); increase input.spacing");
    }
}

/// The 125 cell offsets within ±2 on each axis, by distance from the centre cell.
const std::array<std::array<int, 3>, 125> kNearestFirst = [] {
    std::array<std::array<int, 3>, 125> o{};
    std::size_t n = 0;
    for (int x = -2; x <= 2; ++x)
        for (int y = -2; y <= 2; ++y)
            for (int z = -2; z <= 2; ++z) o[n++] = {x, y, z};
    std::stable_sort(o.begin(), o.end(), [](const auto& a, const auto& b) {
        return a[0] * a[0] + a[1] * a[1] + a[2] * a[2] < b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
    });
    return o;
}();

/// Dense background grid for minimum-distance queries (Bridson): cells of edge r/√3 hold at most
/// one accepted point each.
class DiskGrid
{
public:
    DiskGrid(const openvdb::BBoxd& box, double r) : mLo(box.min()), mR2(r * r), mCell(r / std::sqrt(3.0))
    {
        for (int a = 0; a < 3; ++a) mDim[a] = std::max(1, int(std::ceil((box.max()[a] - box.min()[a]) / mCell)) + 1);
        const double cells = double(mDim[0]) * mDim[1] * mDim[2];
        checkCount(cells / 8.0);
        mCells.assign(std::size_t(cells), -1);
    }
    std::array<int, 3> cellOf(const Vec3d& p) const
    {
        std::array<int, 3> c;
        for (int a = 0; a < 3; ++a) c[a] = std::clamp(int((p[a] - mLo[a]) / mCell), 0, mDim[a] - 1);
        return c;
    }
    std::size_t index(const std::array<int, 3>& c) const
    {
        return (std::size_t(c[0]) * std::size_t(mDim[1]) + std::size_t(c[1])) * std::size_t(mDim[2]) + std::size_t(c[2]);
    }
    /// No accepted point closer than r to p: the cells within ±2 of p's, nearest first (a dart is
    /// mostly refused by a point in the 27 cells around it, so the search usually ends early; the
    /// answer does not depend on the order).
    bool free(const Vec3d& p, const std::vector<Vec3d>& pts) const
    {
        const auto c = cellOf(p);
        for (const auto& o : kNearestFirst) {
            const int x = c[0] + o[0], y = c[1] + o[1], z = c[2] + o[2];
            if (x < 0 || y < 0 || z < 0 || x >= mDim[0] || y >= mDim[1] || z >= mDim[2]) continue;
            const std::int64_t q = mCells[index({x, y, z})];
            if (q >= 0 && (pts[std::size_t(q)] - p).lengthSqr() < mR2) return false;
        }
        return true;
    }
    void insert(const Vec3d& p, std::int64_t id) { mCells[index(cellOf(p))] = id; }

private:
    Vec3d mLo;
    double mR2, mCell;
    std::array<int, 3> mDim{};
    std::vector<std::int64_t> mCells;
};

std::vector<Vec3d> poissonDisk(const openvdb::BBoxd& box, double r, std::uint64_t seed)
{
    const Vec3d ext = box.extents();
    checkCount(ext[0] * ext[1] * ext[2] / (r * r * r));
    DiskGrid grid(box, r);
    HashRng rng{seed, 0x5D};
    std::vector<Vec3d> pts;
    std::vector<std::size_t> active;
    const Vec3d first(box.min()[0] + rng.next() * ext[0], box.min()[1] + rng.next() * ext[1],
                      box.min()[2] + rng.next() * ext[2]);
    pts.push_back(first);
    grid.insert(first, 0);
    active.push_back(0);
    constexpr int kTries = 30;
    while (!active.empty()) {
        const std::size_t ai = std::min(active.size() - 1, std::size_t(rng.next() * double(active.size())));
        const Vec3d p = pts[active[ai]];
        bool placed = false;
        for (int t = 0; t < kTries && !placed; ++t) {
            // Uniform in the spherical shell r … 2r (by volume).
            const double u = rng.next(), z = 2.0 * rng.next() - 1.0, phi = 2.0 * M_PI * rng.next();
            const double rad = r * std::cbrt(1.0 + 7.0 * u);
            const double s = std::sqrt(std::max(0.0, 1.0 - z * z));
            const Vec3d q = p + rad * Vec3d(s * std::cos(phi), s * std::sin(phi), z);
            if (!box.isInside(q) || !grid.free(q, pts)) continue;
            grid.insert(q, std::int64_t(pts.size()));
            active.push_back(pts.size());
            pts.push_back(q);
            placed = true;
        }
        if (!placed) {
            active[ai] = active.back();
            active.pop_back();
        }
    }
    return pts;
}

} // namespace

std::vector<Vec3d> placeSpots(const SpotPlacement& p, const openvdb::BBoxd& box)
{
    if (!(p.spacing > 0) || !std::isfinite(p.spacing)) throw InputError("spot spacing must be > 0");
    const double d = p.spacing;
    const Vec3d ext = box.extents();
    checkCount(ext[0] * ext[1] * ext[2] / (d * d * d));
    std::vector<Vec3d> out;
    switch (p.distribution) {
    case SpotDistribution::Regular:
    case SpotDistribution::Jittered: {
        const bool jitter = p.distribution == SpotDistribution::Jittered;
        // Lattice cells that can contribute a point inside the box (jitter moves ≤ d/2).
        int lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
            lo[a] = int(std::floor(box.min()[a] / d)) - 1;
            hi[a] = int(std::floor(box.max()[a] / d)) + 1;
        }
        for (int i = lo[0]; i <= hi[0]; ++i)
            for (int j = lo[1]; j <= hi[1]; ++j)
                for (int k = lo[2]; k <= hi[2]; ++k) {
                    Vec3d c((i + 0.5) * d, (j + 0.5) * d, (k + 0.5) * d);
                    if (jitter) {
                        for (int a = 0; a < 3; ++a) c[a] += (uniformAt(p.seed, i, j, k, a) - 0.5) * p.jitter * d;
                    }
                    if (box.isInside(c)) out.push_back(c);
                }
        break;
    }
    case SpotDistribution::Random: {
        const auto n = std::uint64_t(std::llround(ext[0] * ext[1] * ext[2] / (d * d * d)));
        out.reserve(n);
        for (std::uint64_t s = 0; s < n; ++s) {
            Vec3d c;
            for (int a = 0; a < 3; ++a)
                c[a] = box.min()[a] + uniformAt(p.seed, int(std::uint32_t(s)), int(s >> 32), 0x7A, a) * ext[a];
            out.push_back(c);
        }
        break;
    }
    case SpotDistribution::Poisson: out = poissonDisk(box, kPoissonRadius * d, p.seed); break;
    }
    return out;
}

std::vector<Vec3d> selectEvenly(const std::vector<Vec3d>& candidates, double minDistance, std::uint64_t seed)
{
    if (candidates.empty()) return {};
    openvdb::BBoxd box(candidates.front(), candidates.front());
    for (const auto& c : candidates) box.expand(c);
    DiskGrid grid(box, minDistance);
    std::vector<std::pair<std::uint64_t, std::uint32_t>> order(candidates.size());
    for (std::size_t i = 0; i < candidates.size(); ++i)
        order[i] = {hashCoord(seed, int(std::uint32_t(i)), int(i >> 32), 0x5E), std::uint32_t(i)};
    std::sort(order.begin(), order.end());
    std::vector<Vec3d> out;
    for (const auto& [h, i] : order) {
        const Vec3d& c = candidates[i];
        if (!grid.free(c, out)) continue;
        grid.insert(c, std::int64_t(out.size()));
        out.push_back(c);
    }
    return out;
}

SpotStats spotStatistics(const std::vector<Vec3d>& spots, const openvdb::BBoxd& box, double spacing,
                         std::uint64_t seed, int probes)
{
    SpotStats st;
    st.count = spots.size();
    if (spots.size() < 2) return st;
    // Nearest neighbours through buckets of edge d, searching ±2 buckets (distances < 2d are exact;
    // a spot with no neighbour that close counts 2d).
    const double cell = spacing;
    std::array<int, 3> dim;
    for (int a = 0; a < 3; ++a) dim[a] = std::max(1, int(std::ceil(box.extents()[a] / cell)) + 1);
    auto cellOf = [&](const Vec3d& p) {
        std::array<int, 3> c;
        for (int a = 0; a < 3; ++a) c[a] = std::clamp(int((p[a] - box.min()[a]) / cell), 0, dim[a] - 1);
        return c;
    };
    auto idx = [&](int x, int y, int z) { return (std::size_t(x) * dim[1] + std::size_t(y)) * dim[2] + std::size_t(z); };
    const std::size_t nBuckets = std::size_t(dim[0]) * std::size_t(dim[1]) * std::size_t(dim[2]);
    std::vector<std::vector<std::uint32_t>> buckets(nBuckets);
    for (std::size_t i = 0; i < spots.size(); ++i) {
        const auto c = cellOf(spots[i]);
        buckets[idx(c[0], c[1], c[2])].push_back(std::uint32_t(i));
    }
    double minD2 = 1e300, sumNearest = 0;
    for (std::size_t i = 0; i < spots.size(); ++i) {
        const auto c = cellOf(spots[i]);
        double best = 4.0 * spacing * spacing;
        for (int x = std::max(0, c[0] - 2); x <= std::min(dim[0] - 1, c[0] + 2); ++x)
            for (int y = std::max(0, c[1] - 2); y <= std::min(dim[1] - 1, c[1] + 2); ++y)
                for (int z = std::max(0, c[2] - 2); z <= std::min(dim[2] - 1, c[2] + 2); ++z)
                    for (std::uint32_t j : buckets[idx(x, y, z)])
                        if (j != i) best = std::min(best, (spots[j] - spots[i]).lengthSqr());
        minD2 = std::min(minD2, best);
        sumNearest += std::sqrt(best);
    }
    st.minDistance = std::sqrt(minD2);
    st.meanNearest = sumNearest / double(spots.size());

    // Disc probes: centre inside the box shrunk by the disc radius, so each disc is fully inside.
    const double rho = 4.0 * spacing;
    const Vec3d lo = box.min() + Vec3d(rho), hi = box.max() - Vec3d(rho);
    if (!(hi[0] > lo[0] && hi[1] > lo[1] && hi[2] > lo[2])) return st;
    HashRng rng{seed, 0x57};
    auto cov = [](const std::vector<double>& counts) {
        double m = 0, v = 0;
        for (double c : counts) m += c;
        m /= double(counts.size());
        for (double c : counts) v += (c - m) * (c - m);
        v /= double(counts.size());
        return m > 0 ? std::sqrt(v) / m : 0.0;
    };
    auto count = [&](const Vec3d& centre, const Vec3d& n, double halfThick) {
        double c = 0;
        for (const auto& s : spots) {
            const Vec3d r = s - centre;
            const double h = r.dot(n);
            if (std::abs(h) >= halfThick) continue;
            if ((r - h * n).lengthSqr() < rho * rho) c += 1;
        }
        return c;
    };
    std::vector<double> tilted, axis;
    std::size_t empty = 0;
    for (int p = 0; p < probes; ++p) {
        const Vec3d centre(lo[0] + rng.next() * (hi[0] - lo[0]), lo[1] + rng.next() * (hi[1] - lo[1]),
                           lo[2] + rng.next() * (hi[2] - lo[2]));
        const double z = 2.0 * rng.next() - 1.0, phi = 2.0 * M_PI * rng.next();
        const double s = std::sqrt(std::max(0.0, 1.0 - z * z));
        tilted.push_back(count(centre, Vec3d(s * std::cos(phi), s * std::sin(phi), z), 0.25 * spacing));
        Vec3d n(0.0);
        n[std::min(2, int(rng.next() * 3.0))] = 1.0;
        axis.push_back(count(centre, n, 0.125 * spacing));
        if (axis.back() == 0) ++empty;
    }
    st.planeCov = cov(tilted);
    st.axisPlaneCov = cov(axis);
    st.emptyAxisFraction = double(empty) / double(probes);
    return st;
}

} // namespace lic

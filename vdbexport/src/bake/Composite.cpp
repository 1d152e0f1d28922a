#include "Composite.h"

#include "lic/composite/Animation.h"
#include "lic/util/Parallel.h"
#include "lic/field/Region.h"
#include "lic/texture/Spots.h"

#include <tbb/parallel_for.h>

#include "lic/util/Error.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <cmath>
#include <cstring>

namespace vdbexport::pipeline {

template<typename GridT>
typename GridT::Ptr LeafSet<GridT>::release(const lic::OutputDomain& domain, const std::string& name)
{
    auto grid = GridT::create(openvdb::zeroVal<ValueT>());
    for (auto& leaf : mLeaves)
        if (leaf && !leaf->isEmpty()) grid->tree().addLeaf(leaf.release());
    mLeaves.clear();
    grid->setTransform(domain.transform()->copy());
    grid->setName(name);
    if constexpr (std::is_floating_point_v<ValueT>) {
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    } else {
        grid->setVectorType(openvdb::VEC_INVARIANT);
    }
    return grid;
}

namespace {

using FloatLeaf = openvdb::FloatTree::LeafNodeType;
using VecLeaf = openvdb::Vec3STree::LeafNodeType;

/// The leaf of block b in `set`, made when the block gets its first kept voxel.
template<typename Set>
auto& leafOf(Set& set, std::size_t b, const openvdb::Coord& origin)
{
    auto* leaf = set.at(b);
    return leaf ? *leaf : set.make(b, origin);
}

} // namespace

Compositor::Compositor(const Plan& plan, const lic::VelocityField& field, const lic::OutputDomain& domain,
                       const lic::BrickLayout& layout, ScalarSet& scalars, Input& input, const lic::Colormap* cmap,
                       const Ranges& ranges)
    : mPlan(plan)
    , mField(field)
    , mDomain(domain)
    , mScalars(scalars)
    , mInput(input)
    , mColormap(cmap)
    , mRanges(ranges)
{
    const Recipe& r = plan.recipe;
    const std::size_t blocks = domain.blockCount();
    if (r.width) mWidthGrid = ScalarField(scalars.get(r.width->scalar));
    if (plan.roiPost) mRoiGrid = ScalarField(scalars.get(r.roi->scalar));
    if (r.color) mColorGrid = ScalarField(scalars.get(r.color->scalar));
    const bool keepRaw = !plan.spots || plan.frames > 1;
    if (keepRaw) {
        mRawLeaves.resize(std::size_t(plan.rawChannels));
        for (auto& set : mRawLeaves) set.init(blocks);
        if (plan.spots && r.width && plan.levels > 1) mWidthLeaves.init(blocks);
        if (plan.roiPost) mRoiLeaves.init(blocks);
    } else {
        mDensity.init(blocks);
        mHalo.init(blocks);
        if (r.output.writeSeries) {
            mLines.resize(std::size_t(plan.levels));
            mHalos.resize(std::size_t(plan.levels));
            for (auto& set : mLines) set.init(blocks);
            for (auto& set : mHalos) set.init(blocks);
        }
    }
    if (r.output.writeInput) mInputLeaves.init(blocks);
    if (r.output.writeTangent) mTangentLeaves.init(blocks);
    if (r.color) {
        mColorLeaves.init(blocks);
        mScalarLeaves.init(blocks);
    }
    if (plan.spots && r.output.writeInput) {
        mInputSpots.emplace(mInput.spots, std::array<double, 1>{r.input.radii[0]}, r.input.haloScale);
    }
    mMoments.assign(layout.size(), Moments{});
}

template<typename Raw>
Compositor::SpotVoxel Compositor::composeSpots(const Raw& raw, float widthT, float roi) const
{
    const int K = mPlan.levels;
    SpotVoxel v;
    for (int k = 0; k < K; ++k) {
        const float li = float(1.0 / mPlan.linePeak[std::size_t(k)]), hi = float(1.0 / mPlan.haloPeak[std::size_t(k)]);
        v.lines[k] = std::clamp(raw(k) * li, 0.0f, 1.0f);
        v.halos[k] = std::max(std::clamp(raw(K + k) * hi, 0.0f, 1.0f), v.lines[k]); // halo ⊇ line
    }
    if (mPlan.recipe.width && K > 1) {
        // Blend the two levels around t·(K − 1): continuous in t, so no seams.
        const double u = double(widthT) * double(K - 1);
        const int k0 = std::min(K - 2, int(u));
        const float w = float(u - k0);
        v.density = (1.0f - w) * v.lines[k0] + w * v.lines[k0 + 1];
        v.halo = (1.0f - w) * v.halos[k0] + w * v.halos[k0 + 1];
    } else {
        v.density = v.lines[0];
        v.halo = v.halos[0];
    }
    if (mPlan.roiPost) {
        v.density *= roi;
        v.halo *= roi;
        for (int k = 0; k < K; ++k) {
            v.lines[k] *= roi;
            v.halos[k] *= roi;
        }
    }
    return v;
}

void Compositor::consume(const lic::BrickChannels& bc)
{
    Moments moments;
    for (std::size_t i = 0; i < bc.brick->blocks.size(); ++i)
        if (!bc.blockTouched || bc.blockTouched[i]) consumeBlock(bc, i, moments);
    mMoments[bc.index] = moments;
}

void Compositor::consumeBlock(const lic::BrickChannels& bc, std::size_t i, Moments& moments)
{
    constexpr std::size_t V = lic::OutputDomain::kBlockVoxels;
    const Recipe& r = mPlan.recipe;
    const std::size_t b = bc.brick->blocks[i];
    const openvdb::Coord origin = mDomain.blockOrigin(b);
    const auto& mask = mDomain.blockMask(b);
    const int C = mPlan.textureChannels, R = mPlan.rawChannels, frames = mPlan.frames;
    const lic::NoiseTexture* noise = (!mPlan.spots && r.output.writeInput) ? &(*mInput.noise)(*bc.brick) : nullptr;
    const double minSpeed = mField.maxSpeed() * 1e-6;

    for (auto on = mask.beginOn(); on; ++on) {
        const std::size_t off = on.pos();
        const openvdb::Coord ijk = mDomain.coordOf(b * V + off);
        const openvdb::Vec3d world = mDomain.worldOf(ijk);
        auto raw = [&](int c) { return bc.block(i, c)[off]; };
        float widthT = 0.0f;
        if (mWidthGrid) {
            const double t = std::clamp((double(mWidthGrid.at(world)) - mRanges.width[0]) /
                                            (mRanges.width[1] - mRanges.width[0]),
                                        0.0, 1.0);
            widthT = float(r.width->invert ? 1.0 - t : t);
        }
        const float roi = mRoiGrid ? lic::roiWeight(mRoiGrid.at(world), r.roi->range[0], r.roi->range[1]) : 1.0f;

        bool keep = true;
        if (mPlan.spots) {
            if (frames == 1) {
                const SpotVoxel sv = composeSpots(raw, widthT, roi);
                keep = sv.density > kSparseEpsilon || sv.halo > kSparseEpsilon;
                if (!keep) continue;
                leafOf(mDensity, b, origin).setValueOn(openvdb::Index(off), sv.density);
                leafOf(mHalo, b, origin).setValueOn(openvdb::Index(off), sv.halo);
                for (std::size_t k = 0; k < mLines.size(); ++k) {
                    leafOf(mLines[k], b, origin).setValueOn(openvdb::Index(off), sv.lines[k]);
                    leafOf(mHalos[k], b, origin).setValueOn(openvdb::Index(off), sv.halos[k]);
                }
            } else {
                // Kept when any frame of the loop shows line or halo here, so every frame file
                // has the same topology.
                keep = false;
                for (int f = 1; f <= frames && !keep; ++f) {
                    const lic::FramePhase ph(f, frames);
                    const SpotVoxel sv = composeSpots(
                        [&](int c) {
                            return lic::rippleFrameValue(raw(c), raw(C + c), raw(2 * C + c), raw(3 * C), raw(3 * C + 1), ph);
                        },
                        widthT, roi);
                    keep = sv.density > kSparseEpsilon || sv.halo > kSparseEpsilon;
                }
                if (!keep) continue;
            }
        } else {
            const float v1 = frames > 1 ? lic::rippleFrameValue(raw(0), raw(1), raw(2), raw(3), raw(4), lic::FramePhase(1, frames))
                                        : raw(0);
            moments.sum += v1;
            moments.sumSq += double(v1) * v1;
            moments.count += 1;
            moments.lo = std::min(moments.lo, v1);
            moments.hi = std::max(moments.hi, v1);
        }
        if (!mRawLeaves.empty()) {
            for (int c = 0; c < R; ++c) leafOf(mRawLeaves[std::size_t(c)], b, origin).setValueOn(openvdb::Index(off), raw(c));
            if (mWidthLeaves.enabled()) leafOf(mWidthLeaves, b, origin).setValueOn(openvdb::Index(off), widthT);
            if (mRoiLeaves.enabled()) leafOf(mRoiLeaves, b, origin).setValueOn(openvdb::Index(off), roi);
        }

        // Grids shared by every frame.
        if (mInputLeaves.enabled()) {
            float v = 0.0f;
            if (noise) {
                v = noise->voxel(ijk);
            } else {
                // The narrowest line level's spot texture at the voxel centre.
                float s[2];
                mInputSpots->sample(ijk.asVec3d(), s);
                v = std::min(s[0], 1.0f);
            }
            leafOf(mInputLeaves, b, origin).setValueOn(openvdb::Index(off), v);
        }
        if (mTangentLeaves.enabled()) {
            // Unit flow direction at the voxel centre (zero at critical points), for illuminated
            // lines in renderers.
            openvdb::Vec3s t(0.0f);
            openvdb::Vec3d v;
            if (mField.sample(world, v)) {
                const double len = v.length();
                if (len > minSpeed) t = openvdb::Vec3s(v / len);
            }
            leafOf(mTangentLeaves, b, origin).setValueOn(openvdb::Index(off), t);
        }
        if (mColorGrid) {
            const double t = std::clamp((double(mColorGrid.at(world)) - mRanges.color[0]) /
                                            (mRanges.color[1] - mRanges.color[0]),
                                        0.0, 1.0);
            leafOf(mScalarLeaves, b, origin).setValueOn(openvdb::Index(off), float(t));
            leafOf(mColorLeaves, b, origin).setValueOn(openvdb::Index(off), openvdb::Vec3s(mColormap->linear(t)));
        }
    }
}

void Compositor::finish()
{
    Moments all;
    for (const Moments& m : mMoments) { // brick order: the same sums for any thread count
        all.sum += m.sum;
        all.sumSq += m.sumSq;
        all.count += m.count;
        all.lo = std::min(all.lo, m.lo);
        all.hi = std::max(all.hi, m.hi);
    }
    mMoments.clear();
    if (all.count == 0) return;
    mRaw.mean = all.sum / all.count;
    mRaw.stddev = std::sqrt(std::max(0.0, all.sumSq / all.count - mRaw.mean * mRaw.mean));
    mRaw.min = all.lo;
    mRaw.max = all.hi;
}

std::string Compositor::packMoments(const std::vector<std::size_t>& ids) const
{
    std::string out;
    for (std::size_t id : ids) {
        const std::uint64_t i = id;
        out.append(reinterpret_cast<const char*>(&i), sizeof i);
        out.append(reinterpret_cast<const char*>(&mMoments.at(id)), sizeof(Moments));
    }
    return out;
}

void Compositor::unpackMoments(const std::string& bytes)
{
    constexpr std::size_t kRecord = sizeof(std::uint64_t) + sizeof(Moments);
    if (bytes.size() % kRecord != 0) throw lic::Error("malformed brick statistics message");
    for (std::size_t at = 0; at < bytes.size(); at += kRecord) {
        std::uint64_t id = 0;
        std::memcpy(&id, bytes.data() + at, sizeof id);
        if (id >= mMoments.size()) throw lic::Error("brick statistics for brick " + std::to_string(id) + " out of range");
        std::memcpy(&mMoments[id], bytes.data() + at + sizeof id, sizeof(Moments));
    }
}

openvdb::GridPtrVec Compositor::frame(int f)
{
    const Recipe& r = mPlan.recipe;
    const int C = mPlan.textureChannels, K = mPlan.levels, frames = mPlan.frames;
    const bool last = f == frames;
    const std::size_t blocks = mDomain.blockCount();
    openvdb::GridPtrVec grids;

    if (mPlan.spots && frames == 1) {
        grids.push_back(mDensity.release(mDomain, "density"));
        grids.push_back(mHalo.release(mDomain, "halo"));
        for (int k = 0; k < int(mLines.size()); ++k) {
            grids.push_back(mLines[std::size_t(k)].release(mDomain, "density_w" + std::to_string(k + 1)));
            grids.push_back(mHalos[std::size_t(k)].release(mDomain, "halo_w" + std::to_string(k + 1)));
        }
    } else {
        // Compose this frame leaf by leaf from the kept channels.
        const lic::FramePhase ph(f, frames);
        const bool stretch = mPlan.stretch && mRaw.stddev >= 1e-6;
        constexpr double kSigmas = 2.5; // as lic::contrastStretch
        const double lo = mRaw.mean - kSigmas * mRaw.stddev, scale = stretch ? 1.0 / (2.0 * kSigmas * mRaw.stddev) : 1.0;
        LeafSet<openvdb::FloatGrid> density, halo;
        std::vector<LeafSet<openvdb::FloatGrid>> lines, halos;
        density.init(blocks);
        if (mPlan.spots) {
            halo.init(blocks);
            if (r.output.writeSeries) {
                lines.resize(std::size_t(K));
                halos.resize(std::size_t(K));
                for (auto& s : lines) s.init(blocks);
                for (auto& s : halos) s.init(blocks);
            }
        }
        lic::detail::runWithThreads(mPlan.settings.threads, [&] {
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks), [&](const auto& range) {
                for (std::size_t b = range.begin(); b != range.end(); ++b) {
                    const FloatLeaf* raw0 = mRawLeaves[0].at(b);
                    if (!raw0) continue;
                    const openvdb::Coord origin = raw0->origin();
                    auto rawAt = [&](int c, openvdb::Index off) { return mRawLeaves[std::size_t(c)].at(b)->getValue(off); };
                    auto value = [&](int c, openvdb::Index off) {
                        return frames > 1 ? lic::rippleFrameValue(rawAt(c, off), rawAt(C + c, off), rawAt(2 * C + c, off),
                                                                  rawAt(3 * C, off), rawAt(3 * C + 1, off), ph)
                                          : rawAt(c, off);
                    };
                    const FloatLeaf* roiLeaf = mRoiLeaves.enabled() ? mRoiLeaves.at(b) : nullptr;
                    if (!mPlan.spots && last && frames == 1) {
                        // A still: the raw leaf becomes the density leaf in place.
                        for (auto it = mRawLeaves[0].at(b)->beginValueOn(); it; ++it) {
                            double v = *it;
                            if (stretch) v = std::clamp((v - lo) * scale, 0.0, 1.0);
                            if (roiLeaf) v *= roiLeaf->getValue(it.pos());
                            it.setValue(float(v));
                        }
                        continue;
                    }
                    FloatLeaf& d = density.make(b, origin);
                    for (auto it = raw0->cbeginValueOn(); it; ++it) {
                        const openvdb::Index off = it.pos();
                        const float roi = roiLeaf ? roiLeaf->getValue(off) : 1.0f;
                        if (!mPlan.spots) {
                            double v = value(0, off);
                            if (stretch) v = std::clamp((v - lo) * scale, 0.0, 1.0);
                            d.setValueOn(off, float(v * roi));
                            continue;
                        }
                        const float widthT = mWidthLeaves.enabled() ? mWidthLeaves.at(b)->getValue(off) : 0.0f;
                        const SpotVoxel sv = composeSpots([&](int c) { return value(c, off); }, widthT, roi);
                        d.setValueOn(off, sv.density);
                        leafOf(halo, b, origin).setValueOn(off, sv.halo);
                        for (int k = 0; k < int(lines.size()); ++k) {
                            leafOf(lines[std::size_t(k)], b, origin).setValueOn(off, sv.lines[k]);
                            leafOf(halos[std::size_t(k)], b, origin).setValueOn(off, sv.halos[k]);
                        }
                    }
                }
            });
        });
        if (!mPlan.spots && last && frames == 1) {
            grids.push_back(mRawLeaves[0].release(mDomain, "density"));
        } else {
            grids.push_back(density.release(mDomain, "density"));
            if (mPlan.spots) {
                grids.push_back(halo.release(mDomain, "halo"));
                for (int k = 0; k < int(lines.size()); ++k) {
                    grids.push_back(lines[std::size_t(k)].release(mDomain, "density_w" + std::to_string(k + 1)));
                    grids.push_back(halos[std::size_t(k)].release(mDomain, "halo_w" + std::to_string(k + 1)));
                }
            }
        }
        if (last) { // the kept channels are not needed any more
            mRawLeaves.clear();
            mWidthLeaves = {};
            mRoiLeaves = {};
        }
    }

    if (!mStaticBuilt) {
        mStaticBuilt = true;
        if (mInputLeaves.enabled()) mStatic.push_back(mInputLeaves.release(mDomain, "input"));
        if (mTangentLeaves.enabled()) mStatic.push_back(mTangentLeaves.release(mDomain, "tangent"));
        if (mColorLeaves.enabled()) {
            auto color = mColorLeaves.release(mDomain, "color");
            color->insertMeta("licvdb_color_space", openvdb::StringMetadata("scene-linear Rec.709"));
            mStatic.push_back(color);
            mStatic.push_back(mScalarLeaves.release(mDomain, "scalar"));
        }
    }
    grids.insert(grids.end(), mStatic.begin(), mStatic.end());
    return grids;
}

lic::Colormap loadColormap(const std::string& spec)
{
    if (std::filesystem::path(spec).extension() != ".csv") return lic::Colormap::named(spec);
    std::ifstream in(spec);
    if (!in) throw lic::InputError("colormap LUT file \"" + spec + "\" cannot be read");
    std::stringstream text;
    text << in.rdbuf();
    return lic::Colormap::fromCsv(text.str(), spec);
}

Ranges bakeRanges(const Recipe& recipe, ScalarSet& scalars, const lic::OutputDomain& domain,
                  std::optional<lic::Colormap>& cmap, const std::vector<std::uint32_t>* blocks,
                  const HistogramReduce& reduce)
{
    Ranges r;
    if (recipe.width) {
        r.width = recipe.width->range ? *recipe.width->range
                                      : autoRange(ScalarField(scalars.get(recipe.width->scalar)), domain, recipe.threads, blocks, reduce);
    }
    if (recipe.color) {
        cmap = loadColormap(recipe.color->colormap);
        r.color = recipe.color->range ? *recipe.color->range
                                      : autoRange(ScalarField(scalars.get(recipe.color->scalar)), domain, recipe.threads, blocks, reduce);
    }
    return r;
}

} // namespace vdbexport::pipeline

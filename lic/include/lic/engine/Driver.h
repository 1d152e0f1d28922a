// The brick driver every engine runs on: bricks in parallel (one brick per task, one thread per
// brick), per-thread scratch reused from brick to brick, cancellation, progress, and the merge of
// the counters. An engine says what to do with one brick; the driver does the rest, so a
// brick's result depends only on the brick (see engine/Bricks.h) and never on the thread count.
#pragma once

#include "lic/field/Bricks.h"
#include "lic/engine/Settings.h"
#include "lic/field/OutputDomain.h"
#include "lic/util/Parallel.h"
#include "lic/util/Progress.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

namespace lic {

/// One finished brick, as the engines hand it to a bake's sink: for each of `brick->blocks` (in
/// order) `channels` runs of 512 floats in leaf-offset order; inactive voxels hold 0.
struct BrickChannels
{
    std::size_t index = 0;          ///< the brick's id (its number in the whole domain's layout)
    const Brick* brick = nullptr;
    int channels = 0;
    const float* values = nullptr;
    /// Splat: per block, 0 when no spot reached it (its values are then not set); null = all set.
    const std::uint8_t* blockTouched = nullptr;
    const float* block(std::size_t i, int c) const
    {
        return values + (i * std::size_t(channels) + std::size_t(c)) * OutputDomain::kBlockVoxels;
    }
};

/// A bake's receiver of finished bricks. Called from the worker thread that made the brick: it
/// must be thread-safe and its result must not depend on the order bricks arrive in. It may not
/// run TBB work of its own that could pick up another brick (each brick runs isolated, so nested
/// work is safe, but serial is cheaper).
using BrickSink = std::function<void(const BrickChannels&)>;

namespace detail {

/// Writes one block of a brick channel-major, as BrickChannels holds it: dst[k·512 + off(j)] =
/// value(j, k) for the voxels j < n and channels k < K. Eight channels at a time: with many
/// channels (a comet loop's N·C) the rows lie 2 KiB apart, and writing all of them per voxel
/// thrashed the few L1 sets they share (~60 % of a 24-frame splat brick).
template<typename Off, typename Value>
void writeChannelMajor(std::size_t K, std::size_t n, const Off& off, const Value& value, float* dst)
{
    constexpr std::size_t V = OutputDomain::kBlockVoxels, kTile = 8;
    for (std::size_t k0 = 0; k0 < K; k0 += kTile) {
        const std::size_t k1 = std::min(K, k0 + kTile);
        for (std::size_t j = 0; j < n; ++j) {
            const std::size_t o = off(j);
            for (std::size_t k = k0; k < k1; ++k) dst[k * V + o] = value(j, k);
        }
    }
}

/// Run `work(position, brick, worker)` for the bricks at `positions` of `layout` (layout.positions() for
/// all of them), in parallel, one
/// brick per task and each brick on one thread (isolated: a thread waiting inside a brick's nested
/// parallel work cannot pick up another brick and clobber its own worker). `Worker` is per-thread
/// state, default-constructed once per thread and reused; it must have a `LicStats stats` member,
/// which the driver merges over every worker (in any order: the counters are integers).
/// Cancellation is checked before each brick; progress advances by each brick's active voxels
/// after it, unless `perBrickProgress` is false (an engine that reports finer progress itself).
/// @throw lic::Cancelled if `progress` interrupts.
template<typename Worker, typename Work>
LicStats forEachBrick(const BrickLayout& layout, const std::vector<std::size_t>& positions, Progress& progress,
                      bool perBrickProgress, Work&& work)
{
    tbb::enumerable_thread_specific<Worker> workers;
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, positions.size(), 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                checkCancel(progress);
                const Brick& brick = layout[positions[i]];
                tbb::this_task_arena::isolate([&] { work(positions[i], brick, workers.local()); });
                if (perBrickProgress) progress.advance(brick.activeVoxels);
            }
        },
        tbb::simple_partitioner());
    LicStats stats;
    for (const Worker& w : workers) stats += w.stats;
    return stats;
}

} // namespace detail
} // namespace lic

// Threading helpers: the one bound on threads, and cancellation.
#pragma once

#include "lic/util/Error.h"
#include "lic/util/Progress.h"

#include <tbb/global_control.h>

#include <optional>

namespace lic {

/// While it lives, every TBB parallel loop of this process runs on at most `threads` threads
/// (0 = no bound: all cores). The one way licvdb bounds its threads: a bake or render sets it once
/// at the top (`--threads N`, recipe `threads`), so every stage (scalars, field preparation, the
/// output domain, table builds, advection, convolution, compositing) honours it; the library's
/// entry points that take a thread count set it too. Bounds nest: TBB applies the smallest.
class ThreadLimit
{
public:
    explicit ThreadLimit(int threads)
    {
        if (threads > 0) mControl.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    }
    ThreadLimit(const ThreadLimit&) = delete;
    ThreadLimit& operator=(const ThreadLimit&) = delete;

private:
    std::optional<tbb::global_control> mControl;
};

namespace detail {
/// Throw lic::Cancelled if the progress hook asks to stop.
inline void checkCancel(Progress& progress)
{
    if (progress.wasInterrupted()) throw Cancelled();
}
} // namespace detail

} // namespace lic

// Small threading helpers shared by the engines.
#pragma once

#include "lic/util/Error.h"
#include "lic/util/Progress.h"

#include <tbb/task_arena.h>

#include <utility>

namespace lic::detail {

/// Run `fn` in a TBB arena of `threads` workers (0 = all cores).
template<typename Fn>
void runWithThreads(int threads, Fn&& fn)
{
    tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
    arena.execute(std::forward<Fn>(fn));
}

/// Throw lic::Cancelled if the progress hook asks to stop.
inline void checkCancel(Progress& progress)
{
    if (progress.wasInterrupted()) throw Cancelled();
}

} // namespace lic::detail

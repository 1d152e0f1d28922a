// licvdb's heap: jemalloc with transparent huge pages when built with it (LICVDB_JEMALLOC, the
// default where libjemalloc-dev is installed), else the C library's malloc.
#include "Allocator.h"

#ifdef LICVDB_JEMALLOC
#include <jemalloc/jemalloc.h>

#include <cstddef>

// jemalloc reads this at its first allocation (before main). thp:always: every extent it maps is
// marked MADV_HUGEPAGE, so that Debian's default transparent-huge-page mode ("madvise") backs the
// heap with 2 MiB pages: first touching a bake's hundreds of MiB then costs one fault per 2 MiB
// instead of one per 4 KiB (docs/performance.md "Memory: huge pages"). JEMALLOC_CONF or
// MALLOC_CONF in the environment still override it.
extern "C" {
// NOLINTNEXTLINE(cppcoreguidelines-avoid-non-const-global-variables): jemalloc's documented hook
const char* malloc_conf = "thp:always,metadata_thp:auto";
}
#endif

namespace vdbexport::cli {

std::string allocatorDescription()
{
#ifdef LICVDB_JEMALLOC
    const char* version = nullptr;
    const char* thp = nullptr;
    std::size_t size = sizeof(const char*);
    std::string s = "jemalloc";
    if (mallctl("version", static_cast<void*>(&version), &size, nullptr, 0) == 0 && version != nullptr)
        s += std::string(" ") + version;
    size = sizeof(const char*);
    if (mallctl("opt.thp", static_cast<void*>(&thp), &size, nullptr, 0) == 0 && thp != nullptr)
        s += std::string(", transparent huge pages: ") + thp;
    return s;
#else
    return "the C library's malloc";
#endif
}

void useFreshArena()
{
#ifdef LICVDB_JEMALLOC
    unsigned arena = 0;
    std::size_t size = sizeof arena;
    if (mallctl("arenas.create", static_cast<void*>(&arena), &size, nullptr, 0) != 0) return;
    (void)mallctl("thread.tcache.flush", nullptr, nullptr, nullptr, 0);
    (void)mallctl("thread.arena", nullptr, nullptr, static_cast<void*>(&arena), sizeof arena);
#endif
}

} // namespace vdbexport::cli

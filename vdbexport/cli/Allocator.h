// Which heap allocator this licvdb uses (licvdb version prints it).
#pragma once

#include <string>

namespace vdbexport::cli {

/// "jemalloc VERSION, transparent huge pages: MODE" when built with jemalloc (LICVDB_JEMALLOC),
/// else "the C library's malloc".
std::string allocatorDescription();

/// Give this thread an arena of its own (jemalloc), so that what it allocates from now on comes
/// from fresh pages rather than from pages a fork still shares with its parent (each first write
/// to those is a copy). Does nothing with the C library's malloc, or if jemalloc refuses.
void useFreshArena();

} // namespace vdbexport::cli

// Which heap allocator this licvdb uses (licvdb version prints it).
#pragma once

#include <string>

namespace vdbexport::cli {

/// "jemalloc VERSION, transparent huge pages: MODE" when built with jemalloc (LICVDB_JEMALLOC),
/// else "the C library's malloc".
std::string allocatorDescription();

} // namespace vdbexport::cli

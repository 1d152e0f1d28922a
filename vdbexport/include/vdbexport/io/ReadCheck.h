// The checks every .vdb read goes through (VdbCheck.h's two layers), remembered per unchanged file
// in this process; and the read the check's child process runs.
#pragma once

#include "vdbexport/io/VdbCheck.h"

#include <string>

namespace vdbexport::detail {

/// @brief checkVdbStructure(path) then checkInIsolatedProcess(path), each done once per unchanged
///        file (same device, inode, size and modification time) in this process.
/// @throw lic::InputError as those do.
VdbCheckResult checkedVdb(const std::string& path);

/// Forget the files checkedVdb has passed (tests).
void clearCheckedVdbCache();

/// @brief Layer 2's read of a .vdb, as the child process runs it: layer 1, then the file's
///        metadata, grid headers and every grid read through VdbReader, in this process (layer 2
///        must be off here: setReadIsolation("")). Prints "WHO: error: REASON" on stderr on failure.
/// @return the child's exit code: 0 intact, 2 refused (bad input), 1 another failure.
int readCheckMain(const std::string& path, const char* who);

} // namespace vdbexport::detail

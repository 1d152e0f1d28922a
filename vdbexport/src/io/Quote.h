// How licvdb's messages name a file, grid or path: in single quotes. Internal.
#pragma once

#include <string>

namespace vdbexport::detail {

/// 'text', as every message names a file, grid, key or path.
inline std::string q(const std::string& s) { return "'" + s + "'"; }

} // namespace vdbexport::detail

// The one progress helper of the commands that work long (bake, render): a progress bar (or
// lines) on stderr, and Ctrl-C to cancel.
#pragma once

#include "vdbexport/cli/TerminalProgress.h"

#include <lic/util/Progress.h>

#include <nlohmann/json.hpp>

#include <functional>

namespace vdbexport::cli {

/// @brief Run `work` with a TerminalProgress on stderr (silent when `quiet`) that SIGINT (Ctrl-C)
///        asks to cancel. The progress line is ended when `work` returns or throws, so what the
///        command prints next (a summary, an error) starts on a fresh line.
/// @return what `work` returns (the command's JSON summary).
/// @throw what `work` throws (lic::Cancelled after Ctrl-C).
nlohmann::json runWithProgress(bool quiet, TerminalProgress::Style style,
                               const std::function<nlohmann::json(lic::Progress&)>& work);

} // namespace vdbexport::cli

#include "Progress.h"

#include <csignal>
#include <cstdio>

namespace vdbexport::cli {

namespace {

/// The progress SIGINT cancels: the one of the running command, if any.
TerminalProgress* gProgress = nullptr;

extern "C" void onInterrupt(int)
{
    if (gProgress) gProgress->requestCancel();
}

/// Points gProgress at a TerminalProgress while it lives; ends its line and clears gProgress when
/// the scope is left, also by an exception (main()'s catch handlers run after that scope is gone).
class InterruptTarget
{
public:
    explicit InterruptTarget(TerminalProgress& progress)
    {
        gProgress = &progress;
        std::signal(SIGINT, onInterrupt);
    }
    ~InterruptTarget()
    {
        if (gProgress) gProgress->finishLine();
        gProgress = nullptr;
    }
    InterruptTarget(const InterruptTarget&) = delete;
    InterruptTarget& operator=(const InterruptTarget&) = delete;
};

} // namespace

nlohmann::json runWithProgress(bool quiet, TerminalProgress::Style style,
                               const std::function<nlohmann::json(lic::Progress&)>& work)
{
    TerminalProgress progress(quiet, stderr, false, style);
    const InterruptTarget target(progress); // declared after `progress`, so destroyed first
    return work(progress);
}

} // namespace vdbexport::cli

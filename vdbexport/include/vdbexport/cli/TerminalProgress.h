// A progress bar on a terminal: percentage, rate and ETA, redrawn in place with '\r'.
#pragma once

#include <lic/util/Progress.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace vdbexport {

/// lic::Progress that draws `stage [#####.....]  42%  1.2M/s  ETA 0:12` on `out`, and records
/// how long each stage took.
///
/// Drawing happens only when not `quiet` and `out` is a terminal (or `forceEnabled`, for
/// tests, or Style::Lines, for programs reading a pipe); stage durations are recorded either way, for the CLI's --json summary.
/// advance() is thread-safe and cheap (atomic counters; at most ~10 redraws a second, a
/// mutex only around drawing). begin() and end() are called by the thread running the
/// operation, one stage at a time; a begin() while a stage is open ends that stage first.
class TerminalProgress : public lic::Progress
{
public:
    /// Bar: the redrawn line above, on a terminal. Lines: for programs (the Blender add-on),
    /// one `progress FRACTION STAGE` line per redraw (FRACTION in [0, 1], -1 when the total is
    /// unknown), whether or not `out` is a terminal.
    enum class Style { Bar, Lines };

    explicit TerminalProgress(bool quiet, FILE* out = stderr, bool forceEnabled = false, Style style = Style::Bar);
    /// Ends a half-drawn line (see finishLine()).
    ~TerminalProgress() override;

    TerminalProgress(const TerminalProgress&) = delete;
    TerminalProgress& operator=(const TerminalProgress&) = delete;

    /// Start stage `stage` with `total` units of work; `total` = 0 means unknown (no
    /// percentage or ETA, only the count and rate).
    void begin(const std::string& stage, std::uint64_t total) override;
    /// `units` more units are done. Thread-safe.
    void advance(std::uint64_t units) override;
    /// The stage is done: record its duration and, when drawing, print its final line
    /// (100%, rate, total time) followed by a newline. No-op when no stage is open.
    void end() override;
    /// True once requestCancel() was called.
    bool wasInterrupted() override { return mCancel.load(std::memory_order_relaxed); }

    /// Ask the running operation to stop (it then throws lic::Cancelled). Lock-free, so it
    /// may be called from a signal handler or another thread.
    void requestCancel() { mCancel.store(true, std::memory_order_relaxed); }

    /// If a progress line is on screen without its newline (a stage that threw before end()),
    /// end it, so that an error message starts on a fresh line. Call before printing errors.
    void finishLine();

    /// True if this object draws (not quiet, and a terminal or forced).
    bool enabled() const { return mEnabled; }

    /// (stage name, seconds) for every stage that ended, in order. Read it after the
    /// operation, not while stages are running.
    const std::vector<std::pair<std::string, double>>& stageSeconds() const { return mStages; }

private:
    using Clock = std::chrono::steady_clock;

    void draw(bool final); // mMutex held

    FILE* mOut;
    Style mStyle;
    bool mEnabled;
    std::atomic<bool> mCancel{false};

    // Current stage. mDone and mNextDrawNs are touched by workers; the rest only under mMutex
    // or by the thread calling begin()/end().
    std::atomic<std::uint64_t> mDone{0};
    std::atomic<std::int64_t> mNextDrawNs{0}; // Clock time (ns since epoch) of the next redraw
    std::uint64_t mTotal = 0;
    std::string mStage;
    Clock::time_point mStart;
    bool mActive = false;

    std::mutex mMutex;
    std::size_t mLastWidth = 0; // characters of the line on screen, to blank leftovers
    bool mLineOpen = false;     // a line was drawn and not yet ended by a newline
    std::vector<std::pair<std::string, double>> mStages;
};

} // namespace vdbexport

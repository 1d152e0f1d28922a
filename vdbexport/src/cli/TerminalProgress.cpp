#include "vdbexport/cli/TerminalProgress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace vdbexport {
namespace {

constexpr std::int64_t kRedrawNs = 100'000'000; // at most ~10 redraws a second
constexpr int kBarWidth = 24;

std::int64_t nanos(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

/// 950, 12.3k, 4.56M, 7.89G.
std::string siCount(double v)
{
    const char* suffix[] = {"", "k", "M", "G", "T"};
    int i = 0;
    while (v >= 1000.0 && i < 4) {
        v /= 1000.0;
        ++i;
    }
    char buf[32];
    std::snprintf(buf, sizeof(buf), i == 0 ? "%.0f%s" : (v < 10 ? "%.2f%s" : (v < 100 ? "%.1f%s" : "%.0f%s")), v, suffix[i]);
    return buf;
}

/// 0.42s, 12.3s, 2:05, 1:02:03.
std::string duration(double seconds)
{
    char buf[32];
    if (!std::isfinite(seconds) || seconds < 0) return "?";
    if (seconds < 60) {
        std::snprintf(buf, sizeof(buf), seconds < 10 ? "%.2fs" : "%.1fs", seconds);
    } else {
        const auto s = static_cast<long long>(std::llround(seconds));
        if (s < 3600) std::snprintf(buf, sizeof(buf), "%lld:%02lld", s / 60, s % 60);
        else std::snprintf(buf, sizeof(buf), "%lld:%02lld:%02lld", s / 3600, (s / 60) % 60, s % 60);
    }
    return buf;
}

} // namespace

TerminalProgress::TerminalProgress(bool quiet, FILE* out, bool forceEnabled, Style style)
    : mOut(out)
    , mStyle(style)
    , mEnabled(!quiet && out != nullptr && (forceEnabled || style == Style::Lines || ::isatty(::fileno(out)) == 1))
{
}

TerminalProgress::~TerminalProgress() { finishLine(); }

void TerminalProgress::begin(const std::string& stage, std::uint64_t total)
{
    if (mActive) end();
    std::lock_guard<std::mutex> lock(mMutex);
    mStage = stage;
    mTotal = total;
    mDone.store(0, std::memory_order_relaxed);
    mStart = Clock::now();
    mActive = true;
    mNextDrawNs.store(nanos(mStart) + kRedrawNs, std::memory_order_relaxed);
    if (mEnabled) draw(false);
}

void TerminalProgress::advance(std::uint64_t units)
{
    mDone.fetch_add(units, std::memory_order_relaxed);
    if (!mEnabled) return;
    const std::int64_t now = nanos(Clock::now());
    std::int64_t next = mNextDrawNs.load(std::memory_order_relaxed);
    if (now < next) return;
    // One thread wins the right to redraw; the others go back to work.
    if (!mNextDrawNs.compare_exchange_strong(next, now + kRedrawNs, std::memory_order_relaxed)) return;
    std::unique_lock<std::mutex> lock(mMutex, std::try_to_lock);
    if (lock.owns_lock() && mActive) draw(false);
}

void TerminalProgress::end()
{
    if (!mActive) return;
    std::lock_guard<std::mutex> lock(mMutex);
    const double seconds = std::chrono::duration<double>(Clock::now() - mStart).count();
    mStages.emplace_back(mStage, seconds);
    if (mEnabled) draw(true);
    mActive = false;
}

void TerminalProgress::finishLine()
{
    std::lock_guard<std::mutex> lock(mMutex);
    if (mLineOpen) {
        std::fputc('\n', mOut);
        std::fflush(mOut);
        mLineOpen = false;
        mLastWidth = 0;
    }
}

void TerminalProgress::draw(bool final)
{
    const double elapsed = std::chrono::duration<double>(Clock::now() - mStart).count();
    std::uint64_t done = mDone.load(std::memory_order_relaxed);
    if (final && mTotal > 0) done = std::max(done, mTotal);
    const double rate = elapsed > 0 ? double(done) / elapsed : 0.0;

    if (mStyle == Style::Lines) {
        const double fraction = mTotal > 0 ? std::min(1.0, double(done) / double(mTotal)) : -1.0;
        std::fprintf(mOut, "progress %.4f %s\n", fraction, mStage.c_str());
        std::fflush(mOut);
        return;
    }

    std::string line = mStage;
    if (mTotal > 0) {
        const double fraction = std::min(1.0, double(done) / double(mTotal));
        const int filled = static_cast<int>(fraction * kBarWidth);
        char pct[16];
        std::snprintf(pct, sizeof(pct), " %3d%%", static_cast<int>(fraction * 100.0));
        line += " [" + std::string(std::size_t(filled), '#') + std::string(std::size_t(kBarWidth - filled), '.') + "]" + pct;
    } else {
        line += "  " + siCount(double(done));
    }
    if (rate > 0) line += "  " + siCount(rate) + "/s";
    if (final) {
        line += "  done in " + duration(elapsed);
    } else if (mTotal > 0 && rate > 0 && done < mTotal) {
        line += "  ETA " + duration(double(mTotal - done) / rate);
    }

    // Blank what is left of a longer previous line.
    const std::size_t width = line.size();
    if (width < mLastWidth) line += std::string(mLastWidth - width, ' ');
    mLastWidth = final ? 0 : width;

    std::fputc('\r', mOut);
    std::fputs(line.c_str(), mOut);
    if (final) std::fputc('\n', mOut);
    std::fflush(mOut);
    mLineOpen = !final;
}

} // namespace vdbexport

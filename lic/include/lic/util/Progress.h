// Progress and cancellation hook for long operations (after openvdb::util::NullInterrupter).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

namespace lic {

/// Receives progress from long operations; may ask them to stop.
/// Implementations must be thread-safe: `advance` is called from worker threads.
class Progress
{
public:
    virtual ~Progress() = default;
    /// A new stage begins with `total` units of work (voxels, streamlines, ...).
    virtual void begin(const std::string& /*stage*/, std::uint64_t /*total*/) {}
    /// `units` more units of the current stage are done.
    virtual void advance(std::uint64_t /*units*/) {}
    /// The current stage is finished.
    virtual void end() {}
    /// Return true to cancel: the operation then throws lic::Cancelled.
    virtual bool wasInterrupted() { return false; }
};

/// Progress that ignores everything: the default.
inline Progress& nullProgress()
{
    static Progress p;
    return p;
}

} // namespace lic

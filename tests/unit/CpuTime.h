#pragma once
// CPU time for hang guards. A wall-clock bound fails on a busy shared machine (CI, an ASan build
// beside other jobs) although nothing is wrong; CPU time grows only while the code under test
// runs, so a bound on it still catches a runaway loop without flaking under load.

#include <sys/resource.h>

namespace lictest {

inline double seconds(const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); }

/// User + system CPU seconds used so far by this process (all its threads).
inline double processCpuSeconds()
{
    rusage u{};
    ::getrusage(RUSAGE_SELF, &u);
    return seconds(u.ru_utime) + seconds(u.ru_stime);
}

/// User + system CPU seconds used so far by this process's finished, waited-for children and
/// their waited-for descendants (std::system's shell, the licvdb it runs, that one's read child).
inline double childrenCpuSeconds()
{
    rusage u{};
    ::getrusage(RUSAGE_CHILDREN, &u);
    return seconds(u.ru_utime) + seconds(u.ru_stime);
}

} // namespace lictest

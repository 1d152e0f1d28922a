// libFuzzer target: the .vdb read path on arbitrary bytes. The bytes become a file (a memfd, read
// through /proc/self/fd/N) that describeVdb (`licvdb info`: every grid read and described),
// readVelocityGrid and readScalarGrids (`licvdb bake`) read: the structural check
// (checkVdbStructure, layer 1) runs first, then OpenVDB 10 itself. Layer 2 (the child process)
// is off here, so anything the check lets through reaches OpenVDB in this process.
// Any exception other than lic::InputError, any crash, sanitizer report, allocation over the
// -malloc_limit_mb (default: -rss_limit_mb) or time-out is a finding.
#include "vdbexport/io/Info.h"
#include "vdbexport/io/FieldGrids.h"
#include "vdbexport/io/ReadCheck.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include <sys/mman.h>
#include <unistd.h>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    const int fd = ::memfd_create("fuzz.vdb", MFD_CLOEXEC);
    if (fd < 0) std::abort();
    if (size > 0 && ::write(fd, data, size) != static_cast<ssize_t>(size)) std::abort();
    const std::string path = "/proc/self/fd/" + std::to_string(fd);
    vdbexport::detail::clearCheckedVdbCache();
    try {
        (void)vdbexport::describeVdb(path);
    } catch (const lic::InputError&) {
    }
    try {
        (void)vdbexport::readVelocityGrid(path);
    } catch (const lic::InputError&) {
    }
    try {
        (void)vdbexport::readScalarGrids(path);
    } catch (const lic::InputError&) {
    }
    ::close(fd);
    return 0;
}

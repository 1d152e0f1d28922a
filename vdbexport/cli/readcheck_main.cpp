// licvdb-readcheck: layer 2 of the .vdb read defences (docs/inputs.md) as a program of its own.
// `licvdb-readcheck -- FILE` runs layer 1 (the structural walk) and then reads the file's
// metadata, grid headers and every grid with OpenVDB, through VdbReader as licvdb reads them, in
// this process (detail::readCheckMain). `licvdb` forks its checks from a process of its own
// (startReadCheckServer); it starts this program where it cannot, so that whatever a file does to
// OpenVDB's reader (a crash, a hang) stays out of the bake. It links OpenVDB and its own read code
// only (20 shared libraries; licvdb links 27, MPI among them, and loads OpenImageIO and VTK only
// when it needs them), so it starts sooner than `licvdb`.
// Exit 0: intact; 2: refused, with "licvdb-readcheck: error: REASON" on stderr; 1: another failure.
#include "vdbexport/io/ReadCheck.h"

#include <cstring>
#include <iostream>
#include <string>

int main(int argc, char** argv)
{
    const char* who = "licvdb-readcheck";
    if (argc != 3 || std::strcmp(argv[1], "--") != 0) {
        std::cerr << who << ": error: usage: licvdb-readcheck -- FILE.vdb\n";
        return 2;
    }
    return vdbexport::detail::readCheckMain(argv[2], who);
}

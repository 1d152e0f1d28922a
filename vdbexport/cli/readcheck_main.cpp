// licvdb-readcheck: layer 2 of the .vdb read defences (docs/inputs.md) as a program of its own.
// `licvdb-readcheck -- FILE` runs layer 1 (the structural walk) and then reads the file's
// metadata, grid headers and every grid with OpenVDB, through VdbReader as licvdb reads them, in
// this process: it is what `licvdb` starts as the child of every .vdb read,
// so that whatever a file does to OpenVDB's reader (a crash, a hang) stays out of the bake. It
// links OpenVDB and its own read code only (20 shared libraries; licvdb links 27, MPI among them,
// and loads OpenImageIO and VTK only when it needs them), so it starts sooner than `licvdb`.
// Exit 0: intact; 2: refused, with "licvdb-readcheck: error: REASON" on stderr; 1: another failure.
#include "vdbexport/io/VdbIO.h"

#include "lic/util/Error.h"

#include <openvdb/openvdb.h>

#include <cstring>
#include <iostream>
#include <new>
#include <string>

int main(int argc, char** argv)
{
    const char* who = "licvdb-readcheck";
    if (argc != 3 || std::strcmp(argv[1], "--") != 0) {
        std::cerr << who << ": error: usage: licvdb-readcheck -- FILE.vdb\n";
        return 2;
    }
    const std::string path = argv[2];
    try {
        openvdb::initialize();
        // VdbReader runs layer 1 first (checkedVdb), then what licvdb's reads do with the file.
        // (`licvdb info` describes grids already read: nothing of the file's is left to check.)
        vdbexport::detail::VdbReader reader(path);
        (void)reader.fileMetadata();
        (void)reader.gridTypes();
        (void)reader.readAllGrids();
        return 0;
    } catch (const lic::InputError& e) {
        std::cerr << who << ": error: " << e.what() << "\n";
        return 2;
    } catch (const std::bad_alloc&) {
        std::cerr << who << ": error: out of memory\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << who << ": error: " << e.what() << "\n";
        return 1;
    }
}

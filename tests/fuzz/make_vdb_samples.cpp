// make_vdb_samples DIR [RES]: write the sample .vdb files of tests/unit/VdbSamples.h into DIR
// (RES³ voxels each, default 8): the seeds of the fuzz_vdb corpus (tests/fuzz/corpus/vdb).
#include "VdbSamples.h"

#include <cstdlib>
#include <iostream>

int main(int argc, char** argv)
{
    if (argc < 2) {
        std::cerr << "usage: make_vdb_samples DIR [RES]\n";
        return 2;
    }
    const int res = argc > 2 ? std::atoi(argv[2]) : 8;
    std::filesystem::create_directories(argv[1]);
    for (const auto& p : vdb_samples::writeVdbSamples(argv[1], res > 0 ? res : 8))
        std::cout << p << " " << std::filesystem::file_size(p) << "\n";
    return 0;
}

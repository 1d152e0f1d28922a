// Writes the sample meshes of MeshSamples.h for the gallery and docs/inputs.md's worked example:
//   DIR/annulus.vtu   tetrahedra of an annulus (a hole down its middle) holding a swirl with an
//                     axial profile (solid rotation about z plus w = 0.3 (1 - r²))
//   DIR/box-case/     an OpenFOAM case (ASCII polyMesh, U at times 0 and 0.5) of the same flow in a box
//   DIR/box-hex.vtu   with --hex-box only: N³ hexahedra of the box (for memory and time figures
//                     of large meshes: N = 216 is 10 M cells)
// Usage: make_mesh_samples DIR [cells per axis, default 32] [--hex-box]
#include "MeshSamples.h"

#include <cstdlib>
#include <string>
#include <iostream>

int main(int argc, char** argv)
{
    if (argc < 2) {
        std::cerr << "usage: make_mesh_samples DIR [cells per axis]\n";
        return 2;
    }
    const mesh_test::fs::path dir = argv[1];
    const int n = argc > 2 ? std::atoi(argv[2]) : 32;
    if (n < 4 || n > 256) {
        std::cerr << "make_mesh_samples: cells per axis must be in [4, 256]\n";
        return 2;
    }
    mesh_test::fs::create_directories(dir);
    if (argc > 3 && std::string(argv[3]) == "--hex-box") {
        // The annulus' lattice without the cut: every cell kept (inner radius 0, outer √2).
        auto grid = mesh_test::hexBox(n);
        mesh_test::writeVtu(grid, dir / "box-hex.vtu");
        std::cout << "wrote " << (dir / "box-hex.vtu").string() << " (" << grid->GetNumberOfCells() << " cells)\n";
        return 0;
    }
    mesh_test::writeVtu(mesh_test::tetAnnulus(n), dir / "annulus.vtu");
    mesh_test::writeOpenFoamCase(dir / "box-case", std::max(4, n / 2), {"0", "0.5"}, {0.5, 1.0});
    std::cout << "wrote " << (dir / "annulus.vtu").string() << " and " << (dir / "box-case").string() << "\n";
    return 0;
}

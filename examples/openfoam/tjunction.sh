#!/usr/bin/env bash
# The README's worked OpenFOAM example, end to end: run Debian's OpenFOAM v1912 T-junction tutorial
# (pimpleFoam, k-epsilon; about 10 s on 2 cores), convert its latest time to a VDB field, bake a
# dense noise LIC and sparse streamlines with halos coloured by speed, and render both with the
# reference raycaster, and (where Blender is installed) in Cycles with the add-on's look.
#
#   examples/openfoam/tjunction.sh [WORKDIR]     (default out/openfoam-tjunction)
#
# Needs `apt-get install openfoam openfoam-examples` (scripts/install-deps installs them) and a
# built licvdb (scripts/build --target licvdb; LICVDB=path overrides). PARALLEL=2 runs the solver
# decomposed on 2 ranks instead: licvdb then reads the processor directories, no reconstructPar.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
licvdb=${LICVDB:-$root/build/vdbexport/licvdb}
work=${1:-$root/out/openfoam-tjunction}
tutorial=/usr/share/doc/openfoam-examples/examples/incompressible/pimpleFoam/RAS/TJunction
if ! command -v pimpleFoam >/dev/null || [[ ! -d $tutorial ]]; then
    echo "needs OpenFOAM and its tutorials: apt-get install openfoam openfoam-examples" >&2
    exit 2
fi
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}   # Debian's OpenFOAM etc/
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1  # mpirun in a container, as root

# 1. The solver: a copy of the tutorial (Debian gzips its larger files), its mesh, its run.
rm -rf "$work"
mkdir -p "$work"
cp -r "$tutorial" "$work/case"
chmod -R u+w "$work/case"
find "$work/case" -name '*.gz' -exec gunzip -f {} +
cd "$work/case"
blockMesh >log.blockMesh
if [[ ${PARALLEL:-1} -gt 1 ]]; then
    # The tutorial has no decomposeParDict; Debian's scotch is a stub, so split with `simple`.
    cat >system/decomposeParDict <<DICT
FoamFile { version 2.0; format ascii; class dictionary; object decomposeParDict; }
numberOfSubdomains $PARALLEL;
method simple;
coeffs { n (1 $PARALLEL 1); }
DICT
    decomposePar >log.decomposePar
    mpirun -np "$PARALLEL" --oversubscribe pimpleFoam -parallel >log.pimpleFoam
else
    pimpleFoam >log.pimpleFoam
fi
cd "$work"

# 2. What licvdb sees: cells, sizes, the default voxel size, the arrays, the times.
"$licvdb" convert case --list
# 3. The latest time (1.5 s) on a lattice chosen for LIC, with every scalar the solver wrote.
"$licvdb" convert case --out tjunction.vdb
# 4. Bakes: dense noise LIC, and streamlines with halos coloured by speed.
"$licvdb" bake --field tjunction.vdb --out tjunction_noise.vdb --color speed --colormap heated-object
#    The duct is ~10 voxels across at the default voxel size: the lines bake at 4 output voxels
#    per field voxel, 14 apart, so that they stay apart and long enough to show the recirculation.
"$licvdb" bake --field tjunction.vdb --out tjunction_lines.vdb --input spots --spacing 14 --radii 1.5 \
    --upsample 4 --length 60 --color speed --colormap viridis
# 5. Pictures from the reference raycaster (its density window for a noise bake is chosen from the
#    bake: docs/render.md).
"$licvdb" render tjunction_noise.vdb --out tjunction_noise.png --size 800,800 --elevation 60
"$licvdb" render tjunction_lines.vdb --out tjunction_lines.png --size 800,800 --elevation 60 \
    --json >tjunction_lines.camera.json
# 6. Blender: the add-on imports either bake (File > Import > licvdb bake); here Cycles renders the
#    lines from the raycaster's camera with the add-on's look (skipped without Blender).
if command -v "${BLENDER:-blender}" >/dev/null; then
    "${BLENDER:-blender}" -b --factory-startup --python-exit-code 1 -P "$root/tools/blender_render.py" -- \
        tjunction_lines.vdb --camera tjunction_lines.camera.json --out tjunction_cycles.png --size 800 \
        --samples 32 >log.blender 2>&1 || { tail -20 log.blender >&2; exit 1; }
fi
echo
echo "field: $work/tjunction.vdb; bakes: $work/tjunction_noise.vdb, $work/tjunction_lines.vdb"
echo "pictures: $work/tjunction_noise.png, $work/tjunction_lines.png$([[ -f tjunction_cycles.png ]] && echo ", $work/tjunction_cycles.png (Cycles)")"

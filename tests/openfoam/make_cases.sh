#!/usr/bin/env bash
# make_cases.sh CACHE_DIR
#
# Makes small, real OpenFOAM cases for licvdb's tests by running Debian's
# OpenFOAM v1912 tutorials (packages `openfoam`, `openfoam-examples`) with
# shortened end times. Each case takes about a second; all of them together
# a few seconds on 2 cores.
#
# Cases (each CACHE_DIR/<name>/ is a complete OpenFOAM case):
#   boxTurb16                dnsFoam, serial; times 0 0.25 0.5 (0/U is boxTurb's
#                            random field)
#   boxTurb16-Uorig          copy of boxTurb16 plus a stale 0/U.orig: 0/U with
#                            internalField uniform (0 0 0), header `object U;`
#                            (VTK 9.1 reads it as U at time 0)
#   boxTurb16-decomposed     the same box decomposed into 2 and run in parallel
#                            (mpirun -np 2 icoFoam -parallel; dnsFoam cannot run
#                            in parallel: its FFT needs the whole box). Results
#                            only in processor0/ processor1/; the top level
#                            keeps 0/ (the initial field) and constant/polyMesh
#   boxTurb16-reconstructed  reconstructPar of a copy of the decomposed case,
#                            processor*/ removed: the twin to compare with
#   boxTurb16-processorsOnly the decomposed case without top-level 0/ and
#                            constant/polyMesh (system/, constant/*Properties and
#                            processor*/ only)
#   pipeCyclic               simpleFoam, cyclic (AMI) patches, polyhedra from
#                            refineHexMesh; 0/U keeps `#includeEtc` (its coded
#                            inlet is replaced by an equal cylindricalInletVelocity:
#                            OpenFOAM refuses dynamic code as root and Debian ships
#                            no wmake); 0.orig/ kept as the tutorial leaves it
#   TJunction                pimpleFoam RAS, times 0 0.1 0.2 0.3
#   TJunction-decomposed     the same run decomposed into 2 across y = 0 (the
#                            processor interface meets walls; no cyclics) and
#                            run in parallel; results only in processor*/
#   TJunction-reconstructed  reconstructPar of a copy of it, processor*/ removed
#   porousBlockage           pisoFoam laminar; 0/U as shipped, with `#includeEtc`
#
# Idempotent: a case whose CASE/.licvdb-case-stamp matches this script's
# stamp is skipped; others are (re)made in a temporary directory and moved
# into place when complete (a failed step shows its log's tail and leaves
# CACHE_DIR/.tmp.NAME/ for a look). Exit 77 (ctest's skip code) with a NOT RUN line
# when OpenFOAM or its tutorials are not installed.
set -euo pipefail

if [[ $# -ne 1 ]]; then
    echo "usage: $0 CACHE_DIR" >&2
    exit 2
fi
cache=$1

STAMP_VERSION=1
TUTORIALS=${FOAM_TUTORIALS:-/usr/share/doc/openfoam-examples/examples}

# --- OpenFOAM environment ---------------------------------------------------
# Debian's package puts the applications in /usr/bin and etc/ in
# /usr/share/openfoam/etc; its etc/bashrc looks for bin/foamEtcFile, which is
# not shipped, and trips `set -u`. The applications only need WM_PROJECT_DIR
# (to find etc/controlDict and etc/caseDicts): without it every application
# fails with "Could not find mandatory etc entry 'controlDict'".
if ! command -v blockMesh >/dev/null 2>&1; then
    echo "NOT RUN: OpenFOAM is not installed (apt-get install openfoam openfoam-examples)"
    exit 77
fi
if [[ ! -d $TUTORIALS/DNS/dnsFoam/boxTurb16 ]]; then
    echo "NOT RUN: OpenFOAM tutorials not found in $TUTORIALS (apt-get install openfoam-examples)"
    exit 77
fi
if [[ -z ${WM_PROJECT_DIR:-} ]]; then
    for d in /usr/share/openfoam /usr/lib/openfoam/openfoam1912; do
        if [[ -f $d/etc/controlDict ]]; then
            export WM_PROJECT_DIR=$d
            break
        fi
    done
fi
if [[ -z ${WM_PROJECT_DIR:-} ]]; then
    echo "NOT RUN: cannot find OpenFOAM's etc/ (set WM_PROJECT_DIR)"
    exit 77
fi
# OpenMPI refuses root without these (containers, CI)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none   # no CMA in containers

of_version=$(dpkg-query -W -f='${Version}' openfoam 2>/dev/null || true)
if [[ -z $of_version ]]; then
    of_version=$(blockMesh -help 2>&1 | sed -n 's/.*OPENFOAM=\([0-9]*\).*/\1/p' | head -1)
fi
stamp="licvdb openfoam cases v$STAMP_VERSION; openfoam $of_version"

mkdir -p "$cache"
cache=$(cd "$cache" && pwd)
# one maker at a time (ctest -j): the others wait, then find the cases made
exec 9>"$cache/.lock"
flock 9

# --- helpers ------------------------------------------------------------------
run_logged() {   # LOG CMD...: on failure show the log's tail and fail
    local log=$1
    shift
    if ! "$@" >"$log" 2>&1; then
        echo "FAILED in $(pwd): $*" >&2
        tail -n 30 "$log" >&2
        return 1
    fi
}

run() {   # APP [ARGS...]: log to log.APP, as the tutorials' runApplication
    run_logged "log.$1" "$@"
}

run_parallel() {   # N APP [ARGS...]: decomposed run on N ranks, log to log.APP
    local n=$1
    shift
    run_logged "log.$1" mpirun -np "$n" --oversubscribe "$@" -parallel
}

# from_tutorial REL DEST: copy a tutorial, uncompress what Debian gzipped
# (e.g. boxTurb16/0/U.gz: OpenFOAM reads .gz, users' cases rarely are)
from_tutorial() {
    cp -r "$TUTORIALS/$1" "$2"
    chmod -R u+w "$2"
    find "$2" -name '*.gz' -exec gunzip -f {} +
}

set_entry() {   # DICT KEY VALUE
    foamDictionary -entry "$2" -set "$3" "$1" >/dev/null
}

now() { echo "${EPOCHREALTIME/,/.}"; }
elapsed() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

is_made() {
    [[ -f $cache/$1/.licvdb-case-stamp ]] &&
        [[ $(cat "$cache/$1/.licvdb-case-stamp") == "$stamp" ]]
}

# make_case NAME FUNCTION: unless NAME is made with this stamp, run FUNCTION
# in a fresh temporary directory (its path as $1); FUNCTION leaves the case
# in ./case, which is then moved to CACHE_DIR/NAME
make_case() {
    local name=$1 fn=$2
    if is_made "$name"; then
        printf '%-26s up to date\n' "$name"
        return 0
    fi
    local tmp="$cache/.tmp.$name" t0
    t0=$(now)
    rm -rf "$tmp"
    mkdir -p "$tmp"
    (
        cd "$tmp"
        "$fn" "$tmp"
    )
    echo "$stamp" >"$tmp/case/.licvdb-case-stamp"
    rm -rf "${cache:?}/$name"
    mv "$tmp/case" "$cache/$name"
    rm -rf "$tmp"
    printf '%-26s made in %s s\n' "$name" "$(elapsed "$t0")"
}

# write_decomposeParDict "(NX NY NZ)": 2 subdomains, method simple (Debian's
# package has scotch only as a stub: "Attempted to use <scotch> without the
# scotchDecomp library loaded", so the tutorials' own scotch dicts fail)
write_decomposeParDict() {
    cat >system/decomposeParDict <<DICT
FoamFile
{
    version     2.0;
    format      ascii;
    class       dictionary;
    object      decomposeParDict;
}

numberOfSubdomains 2;

method          simple;

coeffs
{
    n           $1;
}
DICT
}

copy_made() {   # NAME: copy an already made case to ./case, without its stamp
    cp -r "$cache/$1" case
    rm -f case/.licvdb-case-stamp
}

# --- boxTurb16 family -----------------------------------------------------------
box_base() {   # blockMesh + boxTurb's random initial field, short end time
    from_tutorial DNS/dnsFoam/boxTurb16 case
    cd case
    run blockMesh
    run boxTurb
    set_entry system/controlDict endTime 0.5
    set_entry system/controlDict writeInterval 0.25
}

mk_boxTurb16() {
    box_base
    run dnsFoam
}

mk_boxTurb16_Uorig() {
    if is_made boxTurb16; then
        copy_made boxTurb16
        cd case
    else
        box_base
        run dnsFoam
    fi
    # A stale copy beside U, as Allrun scripts leave them: same header
    # (`object U;`), same patches, internalField uniform (0 0 0)
    perl -0pe 's/internalField\s+nonuniform\s+List<vector>\s*\d+\s*\(.*?\n\)\s*;/internalField   uniform (0 0 0);/s' \
        0/U >0/U.orig
    grep -q '^internalField   uniform (0 0 0);' 0/U.orig
    grep -q '^internalField   nonuniform' 0/U
}

mk_boxTurb16_decomposed() {
    box_base
    # icoFoam, since dnsFoam aborts in parallel (its Kmesh/FFT needs the whole
    # box: "calculated number of cells is incorrect"). icoFoam needs pFinal
    # and a pressure reference (the box is all cyclic)
    sed -i 's/^    p$/    "(p|pFinal)"/' system/fvSolution
    sed -i 's/^\(    nNonOrthogonalCorrectors 0;\)$/\1\n    pRefCell        0;\n    pRefValue       0;/' \
        system/fvSolution
    grep -q pFinal system/fvSolution
    grep -q pRefCell system/fvSolution
    sed -i 's/^application .*/application     icoFoam;/' system/controlDict
    write_decomposeParDict "(2 1 1)"
    run decomposePar
    run_parallel 2 icoFoam
    # results only in processor*/: the top level keeps 0/ (the initial field)
    [[ -d processor0/0.5 && -d processor1/0.5 && ! -e 0.25 && ! -e 0.5 ]]
}

mk_boxTurb16_reconstructed() {
    copy_made boxTurb16-decomposed
    cd case
    rm -f log.*
    run reconstructPar
    rm -rf processor*
    [[ -d 0.25 && -d 0.5 ]]
}

mk_boxTurb16_processorsOnly() {
    copy_made boxTurb16-decomposed
    cd case
    rm -rf 0 constant/polyMesh
}

# --- other tutorials -----------------------------------------------------------
mk_pipeCyclic() {
    from_tutorial incompressible/simpleFoam/pipeCyclic case
    cd case
    run blockMesh
    run topoSet
    run refineHexMesh c0 -overwrite
    cp -r 0.orig 0
    # The inlet's codedFixedValue (v = 2 Cf ^ x, v_x = 1) needs dynamic code:
    # refused as root ("should not be executed by someone with administrator
    # rights"), and Debian's package has no wmake. The same swirl: axial 1,
    # omega = -2 rad/s about x through the origin. 0/U keeps #includeEtc.
    INLET='inlet
    {
        // tutorial: codedFixedValue "swirl", v = 2 Cf ^ (1 0 0), v.x = 1
        type            cylindricalInletVelocity;
        origin          (0 0 0);
        axis            (1 0 0);
        axialVelocity   1;
        radialVelocity  0;
        rpm             -19.0985931710274; // omega = -2 rad/s
        value           $internalField;
    }' perl -0pi -e 's/inlet\s*\{.*?#\};\s*value\s+\$internalField;\s*\}/$ENV{INLET}/s' 0/U
    grep -q cylindricalInletVelocity 0/U
    grep -q '#includeEtc' 0/U
    set_entry system/controlDict endTime 100
    set_entry system/controlDict writeInterval 50
    run simpleFoam
}

mk_TJunction() {
    from_tutorial incompressible/pimpleFoam/RAS/TJunction case
    cd case
    run blockMesh
    set_entry system/controlDict endTime 0.3
    set_entry system/controlDict writeInterval 0.1
    run pimpleFoam
}

# TJunction decomposed across y = 0 (the processor interface meets the walls,
# no cyclics), run in parallel; and its reconstructed twin
mk_TJunction_decomposed() {
    from_tutorial incompressible/pimpleFoam/RAS/TJunction case
    cd case
    run blockMesh
    set_entry system/controlDict endTime 0.3
    set_entry system/controlDict writeInterval 0.1
    write_decomposeParDict "(1 2 1)"
    run decomposePar
    run_parallel 2 pimpleFoam
    [[ -d processor0/0.3 && -d processor1/0.3 && ! -e 0.3 ]]
}

mk_TJunction_reconstructed() {
    copy_made TJunction-decomposed
    cd case
    rm -f log.*
    run reconstructPar
    rm -rf processor*
    [[ -d 0.1 && -d 0.3 ]]
}

mk_porousBlockage() {
    from_tutorial incompressible/pisoFoam/laminar/porousBlockage case
    cd case
    grep -q '#includeEtc' 0/U
    run blockMesh
    run topoSet
    set_entry system/controlDict endTime 4
    set_entry system/controlDict writeInterval 2
    run pisoFoam
}

echo "OpenFOAM cases in $cache ($stamp)"
t_all=$(now)
make_case boxTurb16 mk_boxTurb16
make_case boxTurb16-Uorig mk_boxTurb16_Uorig
make_case boxTurb16-decomposed mk_boxTurb16_decomposed
make_case boxTurb16-reconstructed mk_boxTurb16_reconstructed
make_case boxTurb16-processorsOnly mk_boxTurb16_processorsOnly
make_case pipeCyclic mk_pipeCyclic
make_case TJunction mk_TJunction
make_case TJunction-decomposed mk_TJunction_decomposed
make_case TJunction-reconstructed mk_TJunction_reconstructed
make_case porousBlockage mk_porousBlockage
printf 'all cases: %s s\n' "$(elapsed "$t_all")"

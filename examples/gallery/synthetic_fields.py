#!/usr/bin/python3
"""Two small synthetic fields for the seed's figures 7, 8 and 10 (depth order of overlapping lines),
written as .vdb files that `licvdb bake` reads like a preset's (python3-openvdb + numpy):

  synthetic_fields.py crossing OUT.vdb   # fig 8: two straight lines crossing at different depths
  synthetic_fields.py weave OUT.vdb [N]  # fig 7: layers of straight lines whose direction turns with depth

Both are N^3 voxels (crossing: N = 33; weave: default 49) of size 1 (world = field index), centred
on the origin.

crossing: v = (1, 0, 0) in front (y < -2), v = (0, 0, 1) behind (y > 2), blended between. The float
grid `seed` is 1 on two tubes (radius 1 voxel): along x at (y, z) = (-6.25, 1.75) and along z at
(x, y) = (1.75, 5.75); a ROI on `seed` with a regular spot lattice of spacing 8 (output voxels at
upsample 2) keeps exactly the lattice rows on the two tube axes: two lines. `hue` is 0 in front and
1 behind (colour by it through two-hues.csv).

weave: v = (cos a, 0, sin a), a = 70° * y / 16: each depth layer y is a sheet of parallel straight
lines, the direction turning with depth, so lines at different depths cross in a front view. `hue`
is a random value per line (constant along each streamline: a hash of its layer and its offset
across the layer), like the seed's randomly coloured lines.
"""
import sys

import numpy as np
import pyopenvdb as vdb

N = 33
C = (N - 1) / 2.0  # index of the centre voxel


def set_size(n):
    global N, C
    N, C = n, (n - 1) / 2.0


def coords():
    i = np.arange(N, dtype=np.float64) - C
    return np.meshgrid(i, i, i, indexing="ij")  # x, y, z (world = index - C)


def smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def crossing():
    x, y, z = coords()
    s = smoothstep((y + 2.0) / 4.0)
    v = np.stack([1.0 - s, np.zeros_like(s), s], axis=-1)
    # Output voxel j (upsample 2) has field index j/2 - 1/4; lattice rows at j = 20 and 44 (y),
    # 36 (z for line A, x for line B) -> field 9.75, 21.75, 17.75 -> world (minus C = 16).
    da = np.hypot(y - (9.75 - C), z - (17.75 - C))
    db = np.hypot(x - (17.75 - C), y - (21.75 - C))
    seed = np.clip(1.0 - np.minimum(da, db) / 2.0, 0.0, 1.0)
    hue = s
    return v, {"seed": seed, "hue": hue}


def weave():
    x, y, z = coords()
    a = np.radians(70.0) * y / C  # +-70 degrees at the front and back faces
    v = np.stack([np.cos(a), np.zeros_like(a), np.sin(a)], axis=-1)
    # Invariant across a streamline: its layer (y) and its offset q across the layer.
    q = -x * np.sin(a) + z * np.cos(a)
    layer = np.floor(y / 3.0)
    band = np.floor(q / 3.0)
    h = np.sin(layer * 12.9898 + band * 78.233) * 43758.5453
    hue = h - np.floor(h)
    return v, {"hue": hue}


def grid_from(array, name, background):
    g = vdb.Vec3SGrid() if array.ndim == 4 else vdb.FloatGrid(background)
    g.copyFromArray(array.astype(np.float32), ijk=(0, 0, 0), tolerance=(0, 0, 0) if array.ndim == 4 else 0)
    g.name = name
    g.transform = vdb.createLinearTransform([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [-C, -C, -C, 1]])
    return g


def main():
    if len(sys.argv) not in (3, 4) or sys.argv[1] not in ("crossing", "weave") or \
            (sys.argv[1] == "crossing" and len(sys.argv) == 4):
        sys.exit(__doc__)
    if sys.argv[1] == "weave":
        set_size(int(sys.argv[3]) if len(sys.argv) == 4 else 49)
    v, scalars = crossing() if sys.argv[1] == "crossing" else weave()
    grids = [grid_from(v, "velocity", None)]
    # Background -1: every voxel of a scalar differs from it, so every voxel stays active.
    grids += [grid_from(a, n, -1.0) for n, a in scalars.items()]
    vdb.write(sys.argv[2], grids=grids)
    print(sys.argv[2])


if __name__ == "__main__":
    main()

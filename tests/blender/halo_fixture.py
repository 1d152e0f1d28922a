"""A synthetic halo bake: two thin lines crossing at different depths, each in a wider halo.

Written with OpenVDB's Python module (pyopenvdb, or openvdb since OpenVDB 12: controls.vdb_module;
Blender's Python is the system Python in Debian's builds) in licvdb's output format:
FOG_VOLUME float grids ``density`` and ``halo`` in [0, 1], halo ≥ density, leaf voxels only (no
tiles: Blender 3.4 renders tiles as empty), plus the sidecar manifest licvdb writes.

World layout (voxel size 1/32, voxel (i, j, k) centred at (i, j, k)/32):
  line A (front): along x at y = 0.5, z = 0.65, x in [0.1, 0.9]
  line B (back):  along y at x = 0.5, z = 0.35, y in [0.1, 0.9]
Seen from +z (looking down) they cross at (0.5, 0.5); B passes behind A.
"""

import json
import os

import numpy as np

N = 32
VOXEL = 1.0 / N
LINE_RADIUS = 1.5  # voxels: density 1 within 0.5, falling linearly to 0 at 1.5
HALO_RADIUS = 3.5  # voxels: halo 1 within 2.5, falling linearly to 0 at 3.5
A = ((0.1, 0.5, 0.65), (0.9, 0.5, 0.65))
B = ((0.5, 0.1, 0.35), (0.5, 0.9, 0.35))


def _segment_distance(p, a, b):
    """Distance (world) from points p (..., 3) to segment a-b."""
    a, b = np.asarray(a), np.asarray(b)
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def volumes():
    """(density, halo) as dense float32 arrays indexed [i, j, k]."""
    idx = np.stack(np.meshgrid(np.arange(N), np.arange(N), np.arange(N), indexing="ij"), axis=-1)
    p = idx * VOXEL
    r = np.minimum(_segment_distance(p, *A), _segment_distance(p, *B)) / VOXEL  # voxels
    density = np.clip(LINE_RADIUS - r, 0.0, 1.0).astype(np.float32)
    halo = np.clip(HALO_RADIUS - r, 0.0, 1.0).astype(np.float32)
    return density, halo


def write(directory, name="crossing"):
    """Write NAME.vdb + NAME.licvdb.json into ``directory``; returns the .vdb path."""
    from controls import vdb_module

    vdb = vdb_module()

    density, halo = volumes()
    assert (halo >= density).all()
    grids, infos = [], []
    for gname, arr in (("density", density), ("halo", halo)):
        g = vdb.FloatGrid()
        g.copyFromArray(arr, ijk=(0, 0, 0), tolerance=0.0)
        g.transform = vdb.createLinearTransform(voxelSize=VOXEL)
        g.name = gname
        g.gridClass = vdb.GridClass.FOG_VOLUME
        lo, hi = g.evalActiveVoxelBoundingBox()
        infos.append({"name": gname, "type": "float", "active_voxels": int(g.activeVoxelCount()),
                      "voxel_size": [VOXEL] * 3,
                      "world_bbox": [[(c - 0.5) * VOXEL for c in lo], [(c + 0.5) * VOXEL for c in hi]]})
        grids.append(g)
    path = os.path.join(str(directory), name + ".vdb")
    vdb.write(path, grids=grids)
    manifest = {"licvdb_version": "test fixture", "recipe": {}, "frames": 1, "cyclic": False,
                "files": [name + ".vdb"], "voxel_size": VOXEL, "colormap": None, "range": None,
                "grids": infos}
    with open(os.path.join(str(directory), name + ".licvdb.json"), "w", encoding="utf-8") as f:
        json.dump(manifest, f, indent=2)
    return path

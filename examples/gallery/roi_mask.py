#!/usr/bin/python3
"""Write the region-of-interest mask of a field as a float grid `mask`, for looking at it (seed
figure 2, top centre): roi_mask.py FIELD.vdb OUT.vdb LO HI [--scalar speed]

The mask is lic::roiWeight (lic/field/Region.h) of the speed |v| at the field's voxels: 1 for
LO <= s <= HI, falling to 0 over 5% of (HI - LO) outside with a smoothstep. (A bake samples the
same mask at each output voxel, trilinearly.) Uses python3-openvdb and numpy.
"""
import sys

import numpy as np
import pyopenvdb as vdb


def roi_weight(s, lo, hi):
    w = 0.05 * (hi - lo)
    smooth = lambda t: np.clip(t, 0, 1) ** 2 * (3 - 2 * np.clip(t, 0, 1))  # noqa: E731
    return np.where(s < lo, smooth(1 - (lo - s) / w), np.where(s > hi, smooth(1 - (s - hi) / w), 1.0))


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    field, out, lo, hi = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
    v = vdb.read(field, "velocity")
    (x0, y0, z0), (x1, y1, z1) = v.evalActiveVoxelBoundingBox()
    arr = np.zeros((x1 - x0 + 1, y1 - y0 + 1, z1 - z0 + 1, 3), dtype=np.float32)
    v.copyToArray(arr, ijk=(x0, y0, z0))
    mask = roi_weight(np.linalg.norm(arr, axis=-1), lo, hi).astype(np.float32)
    g = vdb.FloatGrid(-1.0)  # background -1: every voxel (0 or 1 alike) stays active
    g.copyFromArray(mask, ijk=(x0, y0, z0), tolerance=0)
    g.name = "mask"
    g.transform = v.transform
    vdb.write(out, grids=[g])
    print(out)


if __name__ == "__main__":
    main()

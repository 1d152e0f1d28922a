# Write the OpenVDB 13 sample files of this directory (VDB file format version 225) with
# OpenVDB 13's Python module (Debian sid: python3-openvdb 13.0), e.g. in scripts/test-modern's
# sid chroot:
#   chroot /var/cache/licvdb-modern/sid python3 /src/tests/inputs/openvdb13/make_samples.py /src/tests/inputs/openvdb13
# The values are analytic, so tests/unit/test_vdbcheck.cpp knows them without OpenVDB 13:
# - velocity-v225.vdb: `velocity` (Vec3s, a rotation about the z axis with a drift along it:
#   (-(j - 7.5), i - 7.5, 0.25) at voxel (i, j, k) on 16³ voxels), voxel size 0.1, and `density`
#   (float, 0.05 · (k + 1), stored as half floats), with the module's default compression: the
#   grids and storage of a Blender 5 smoke cache frame.
import sys

import numpy as np
import openvdb as vdb

out = sys.argv[1] if len(sys.argv) > 1 else "."
n = 16
i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
vel = np.stack([-(j - 7.5), i - 7.5, np.full(i.shape, 0.25)], axis=-1).astype(np.float32)
den = (0.05 * (k + 1)).astype(np.float32)


def grids(half):
    v = vdb.Vec3SGrid()
    v.name = "velocity"
    v.copyFromArray(vel, ijk=(0, 0, 0), tolerance=(0.0, 0.0, 0.0))
    v.transform = vdb.createLinearTransform(voxelSize=0.1)
    d = vdb.FloatGrid()
    d.name = "density"
    d.gridClass = vdb.GridClass.FOG_VOLUME
    d.copyFromArray(den, ijk=(0, 0, 0), tolerance=0.0)
    d.transform = vdb.createLinearTransform(voxelSize=0.1)
    d.saveFloatAsHalf = half
    return [v, d]


vdb.write(f"{out}/velocity-v225.vdb", grids=grids(True))
print("OpenVDB", vdb.LIBRARY_VERSION, "wrote", f"{out}/velocity-v225.vdb")

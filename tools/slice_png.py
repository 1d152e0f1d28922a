#!/usr/bin/python3
"""Write one axis-aligned slice of a float grid (default `density`) as a greyscale PNG.

A quick look at a bake before the reference renderer: slice_png.py IN.vdb OUT.png [--axis z]
[--index N] [--grid density] [--scale 2]. Uses Debian's python3-openvdb and numpy only.
"""
import argparse
import struct
import sys
import zlib

import numpy as np
import pyopenvdb as vdb


def write_png(path, img):
    h, w = img.shape
    raw = b"".join(b"\x00" + img[y].tobytes() for y in range(h))
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("vdb")
    ap.add_argument("png")
    ap.add_argument("--grid", default="density")
    ap.add_argument("--axis", choices="xyz", default="z")
    ap.add_argument("--index", type=int, default=None, help="slice index (default: middle)")
    ap.add_argument("--scale", type=int, default=2, help="pixel repeat factor")
    a = ap.parse_args()
    grid = vdb.read(a.vdb, a.grid)
    lo, hi = grid.evalActiveVoxelBoundingBox()
    dims = tuple(h - l + 1 for l, h in zip(lo, hi))
    arr = np.zeros(dims, dtype=np.float32)
    grid.copyToArray(arr, ijk=lo)
    ax = "xyz".index(a.axis)
    idx = dims[ax] // 2 if a.index is None else a.index - lo[ax]
    sl = np.take(arr, idx, axis=ax)
    img = (np.clip(sl, 0, 1) * 255 + 0.5).astype(np.uint8).T[::-1]
    img = np.repeat(np.repeat(img, a.scale, axis=0), a.scale, axis=1)
    write_png(a.png, np.ascontiguousarray(img))
    print(a.png)


if __name__ == "__main__":
    sys.exit(main())

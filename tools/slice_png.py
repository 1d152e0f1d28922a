#!/usr/bin/python3
"""Write one axis-aligned slice of a float grid (default `density`) as a greyscale PNG.

A quick look at a bake before the reference renderer: slice_png.py IN.vdb OUT.png [--axis z]
[--index N] [--grid density] [--scale 2] [--slab N] [--range LO,HI]. Uses Debian's python3-openvdb and numpy only.
`--slab N` writes the maximum over N consecutive slices centred on the index instead of one slice
(e.g. a layer of spot centres one spacing thick, seen as a 2D point distribution).
"""
import argparse
import struct
import sys
import zlib

import numpy as np
import pyopenvdb as vdb


def write_png(path, img):
    h, w = img.shape[:2]
    colour = img.ndim == 3
    raw = b"".join(b"\x00" + img[y].tobytes() for y in range(h))
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2 if colour else 0, 0, 0, 0))
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
    ap.add_argument("--slab", type=int, default=1,
                    help="maximum over this many slices centred on the index (default 1: one slice)")
    ap.add_argument("--range", default="0,1",
                    help="LO,HI: the values shown black to white (default 0,1)")
    ap.add_argument("--color", action="store_true",
                    help="multiply density by the vec3 `color` grid (scene-linear) and write sRGB")
    a = ap.parse_args()
    grid = vdb.read(a.vdb, a.grid)
    lo, hi = grid.evalActiveVoxelBoundingBox()
    dims = tuple(h - l + 1 for l, h in zip(lo, hi))
    arr = np.zeros(dims, dtype=np.float32)
    grid.copyToArray(arr, ijk=lo)
    ax = "xyz".index(a.axis)
    idx = dims[ax] // 2 if a.index is None else a.index - lo[ax]
    first = max(0, idx - (a.slab - 1) // 2)
    slab = np.take(arr, range(first, min(dims[ax], first + a.slab)), axis=ax)
    sl = slab.max(axis=ax)
    lo_v, hi_v = (float(v) for v in a.range.split(","))
    sl = (sl - lo_v) / (hi_v - lo_v)
    if a.color:
        cgrid = vdb.read(a.vdb, "color")
        carr = np.zeros(dims + (3,), dtype=np.float32)
        cgrid.copyToArray(carr, ijk=lo)
        lin = np.clip(np.take(carr, idx, axis=ax) * sl[..., None], 0, 1)
        enc = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(lin, 1 / 2.4) - 0.055)
        img = (enc * 255 + 0.5).astype(np.uint8).transpose(1, 0, 2)[::-1]
    else:
        img = (np.clip(sl, 0, 1) * 255 + 0.5).astype(np.uint8).T[::-1]
    img = np.repeat(np.repeat(img, a.scale, axis=0), a.scale, axis=1)
    write_png(a.png, np.ascontiguousarray(img))
    print(a.png)


if __name__ == "__main__":
    sys.exit(main())

"""Render a licvdb bake in Blender's Cycles with the licvdb add-on's look, optionally through the
camera of a `licvdb render --json` summary (so the picture matches the reference raycaster's):

    licvdb render bake.vdb --out ref.png --size 512,512 --json > ref.json
    blender -b --factory-startup --python-exit-code 1 -P tools/blender_render.py -- \\
        bake.vdb --out cycles.png [--camera ref.json] [--size 512] [--samples 32]

Without --camera, the camera frames the bake from the front (−Y), like `licvdb render`'s default.
The add-on is loaded from this checkout (blender_addon/); nothing is installed.
"""

import argparse
import json
import math
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "blender_addon"))

import addon_utils  # noqa: E402  (Blender's modules, importable only inside Blender)
import bpy  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_render.py", description=__doc__.split("\n\n")[0])
    p.add_argument("bake", help="a licvdb .vdb bake (or any frame of a loop)")
    p.add_argument("--out", required=True, help="output image (.png or .exr)")
    p.add_argument("--camera", help="`licvdb render --json` output whose camera to use")
    p.add_argument("--size", type=int, default=512, help="square image size in pixels [512]")
    p.add_argument("--samples", type=int, default=32, help="Cycles samples per pixel [32]")
    return p.parse_args(argv)


def camera_from_summary(path):
    with open(path, encoding="utf-8") as f:
        b = json.load(f)["camera"]["blender"]
    data = bpy.data.cameras.new("licvdb camera")
    data.type, data.sensor_fit = b["type"], b["sensor_fit"]
    if b["type"] == "ORTHO":
        data.ortho_scale = b["ortho_scale"]
    else:
        data.angle_y = b["angle_y"]
    data.clip_start, data.clip_end = 1e-3, 1e4
    cam = bpy.data.objects.new("licvdb camera", data)
    cam.matrix_world = Matrix(b["matrix_world"])
    return cam


def camera_framing(obj):
    """A 40° perspective camera on −Y looking at the object's bounding box, Z up."""
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    lo = Vector([min(c[a] for c in corners) for a in range(3)])
    hi = Vector([max(c[a] for c in corners) for a in range(3)])
    center, radius = (lo + hi) / 2, (hi - lo).length / 2
    data = bpy.data.cameras.new("licvdb camera")
    data.angle = math.radians(40)
    data.clip_start, data.clip_end = 1e-3, 1e4
    cam = bpy.data.objects.new("licvdb camera", data)
    cam.location = center + Vector((0.0, -radius / math.sin(data.angle / 2), 0.0))
    cam.rotation_euler = (math.radians(90), 0.0, 0.0)
    return cam


def main():
    args = parse_args()
    bpy.ops.wm.read_homefile(use_empty=True)
    addon_utils.enable("licvdb", default_set=True)
    from licvdb import ops_import

    obj = ops_import.import_bake(bpy.context, os.path.abspath(args.bake))
    cam = camera_from_summary(args.camera) if args.camera else camera_framing(obj)
    scene = bpy.context.scene
    scene.collection.objects.link(cam)
    scene.camera = cam
    r = scene.render
    r.resolution_x = r.resolution_y = args.size
    r.resolution_percentage = 100
    r.filepath = os.path.abspath(args.out)
    r.image_settings.file_format = "OPEN_EXR" if args.out.lower().endswith(".exr") else "PNG"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.samples
    t = time.time()
    bpy.ops.render.render(write_still=True)
    print(f"blender_render: wrote {r.filepath} ({args.size}×{args.size}, {args.samples} samples, "
          f"{time.time() - t:.1f} s)")


main()

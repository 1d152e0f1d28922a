"""Render a licvdb bake twice through one camera: its surface preview in EEVEE (the volume hidden)
and the volume in Cycles (the preview hidden, as by default), side by side in one PNG.

EEVEE needs OpenGL, so run it under a virtual X server (the add-on is loaded from this checkout):

    xvfb-run -a -s "-screen 0 1280x1024x24" blender -b --factory-startup --python-exit-code 1 \\
        -P tools/blender_preview_render.py -- out/tabbed-jet_halos.vdb --out docs/images/blender-preview-eevee-vs-cycles.png

Prints each render's time and how well the two pictures' lines overlap (the intersection over
union of the pixels brighter than 0.08 in each).
"""

import argparse
import math
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "blender_addon"))

import addon_utils  # noqa: E402  (Blender's modules, importable only inside Blender)
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_preview_render.py", description=__doc__.split("\n\n")[0])
    p.add_argument("bake", help="a licvdb .vdb bake")
    p.add_argument("--out", required=True, help="output PNG: EEVEE (preview) left, Cycles (volume) right")
    p.add_argument("--size", type=int, default=384, help="each render's width and height [384]")
    p.add_argument("--samples", type=int, default=16, help="Cycles samples [16]")
    return p.parse_args(argv)


def add_camera(obj):
    """A 40° camera looking at the bake's box from the front, a little from the side and above."""
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    center = sum(corners, Vector()) / 8
    radius = max((c - center).length for c in corners)
    data = bpy.data.cameras.new("licvdb camera")
    data.angle = math.radians(40)
    cam = bpy.data.objects.new("licvdb camera", data)
    direction = Vector((-0.55, -1.0, 0.35)).normalized()
    cam.location = center + direction * 0.9 * radius / math.sin(data.angle / 2)
    cam.rotation_euler = direction.to_track_quat("Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam


def eevee_engine(scene):
    """EEVEE's engine id in this Blender (BLENDER_EEVEE in 3.x and 5.x, BLENDER_EEVEE_NEXT in 4.2–4.5)."""
    ids = [i.identifier for i in scene.render.bl_rna.properties["engine"].enum_items]
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in ids else "BLENDER_EEVEE"


def render(path):
    """Render the scene's camera to ``path``; returns (pixels (h, w, 4) top row first, seconds)."""
    scene = bpy.context.scene
    scene.render.filepath = path
    t = time.time()
    bpy.ops.render.render(write_still=True)
    seconds = time.time() - t
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)
    bpy.data.images.remove(img)
    os.remove(path)
    return px, seconds


def mask_iou(a, b, level=0.08):
    """Intersection over union of where two images are brighter than ``level`` (mean of RGB)."""
    ma, mb = a[..., :3].mean(axis=2) > level, b[..., :3].mean(axis=2) > level
    return float((ma & mb).sum()) / max(1, int((ma | mb).sum()))


def main():
    args = parse_args()
    bpy.ops.wm.read_homefile(use_empty=True)
    addon_utils.enable("licvdb", default_set=True)
    from licvdb import ops_import, preview

    obj = ops_import.import_bake(bpy.context, os.path.abspath(args.bake), surface_preview=True)
    pv = preview.preview_of(obj)
    add_camera(obj)
    scene = bpy.context.scene
    r = scene.render
    r.resolution_x = r.resolution_y = args.size
    r.resolution_percentage = 100
    r.image_settings.file_format = "PNG"
    tmp = os.path.abspath(args.out) + ".tmp.png"
    # EEVEE: the preview only.
    scene.render.engine = eevee_engine(scene)
    pv.hide_render, obj.hide_render = False, True
    eevee, t_eevee = render(tmp)
    # Cycles: the volume only (the import's render settings).
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.samples
    pv.hide_render, obj.hide_render = True, False
    cycles, t_cycles = render(tmp)
    row = np.concatenate([eevee, cycles], axis=1)
    img = bpy.data.images.new("comparison", row.shape[1], row.shape[0], alpha=False)
    img.pixels[:] = row.ravel()
    img.filepath_raw = os.path.abspath(args.out)
    img.file_format = "PNG"
    img.save()
    print(f"preview_render: EEVEE (preview, {preview.triangle_count(bpy.context, obj)} triangles) {t_eevee:.1f} s, "
          f"Cycles (volume, {args.samples} samples) {t_cycles:.1f} s; line masks' IoU "
          f"{mask_iou(eevee, cycles):.2f}; wrote {args.out}")


main()

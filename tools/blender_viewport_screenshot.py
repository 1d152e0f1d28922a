"""Screenshots of Blender's 3D viewport showing a licvdb bake with its surface preview.

Needs a window (a virtual X server) and a .blend with Blender's default screen saved without a
splash (an empty scene); the add-on is loaded from this checkout:

    blender -b --factory-startup --python-expr "import bpy; bpy.ops.wm.read_homefile(use_empty=True); \\
        bpy.ops.wm.save_as_mainfile(filepath='/tmp/empty.blend')"
    xvfb-run -a -s "-screen 0 1600x1000x24" blender /tmp/empty.blend -P tools/blender_viewport_screenshot.py -- \\
        out/tabbed-jet_halos.vdb --out docs/images/blender-viewport-preview.png

It imports the bake (with the surface preview), then shoots the 3D view in each shading of
``--shots`` (``material-nopreview``: Material Preview with the preview off, i.e. what the viewport
showed before; ``solid``; ``material``), puts the shots side by side in one PNG, prints the
preview's triangle count and the modifier's evaluation time, and quits.
"""

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "blender_addon"))

import addon_utils  # noqa: E402  (Blender's modules, importable only inside Blender)
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402

SHOTS = {"material-nopreview": ("MATERIAL", False), "solid": ("SOLID", True), "material": ("MATERIAL", True)}


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_viewport_screenshot.py", description=__doc__.split("\n\n")[0])
    p.add_argument("bake", help="a licvdb .vdb bake (or any frame of a loop)")
    p.add_argument("--out", required=True, help="output PNG (the shots side by side)")
    p.add_argument("--shots", default="material-nopreview,solid,material",
                   help="comma-separated: " + ", ".join(SHOTS) + " [all three]")
    p.add_argument("--size", type=int, default=380, help="each shot's height and width in pixels [380]")
    p.add_argument("--view", default="-0.55,-1.0,0.35",
                   help="direction from the bake's centre to the eye, x,y,z [-0.55,-1,0.35]")
    p.add_argument("--coarsen", type=float, default=0.0,
                   help="mesh at this many output voxels (Volume to Mesh voxel size) instead of the bake's grid")
    args = p.parse_args(argv)
    args.shots = [s for s in args.shots.split(",") if s]
    bad = [s for s in args.shots if s not in SHOTS]
    if bad:
        p.error(f"unknown shot(s): {', '.join(bad)}")
    return args


def view3d():
    """(window, area, region, space) of the largest 3D view."""
    win = bpy.context.window_manager.windows[0]
    areas = [a for a in win.screen.areas if a.type == "VIEW_3D"]
    area = max(areas, key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    return win, area, region, area.spaces.active


def aim(space, obj, direction):
    """Point the 3D view at the bake's bound box from ``direction``, perspective, no overlays."""
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    center = sum(corners, Vector()) / 8
    radius = max((c - center).length for c in corners)
    r3d = space.region_3d
    r3d.view_perspective = "PERSP"
    r3d.view_location = center
    r3d.view_rotation = Vector(direction).normalized().to_track_quat("Z", "Y")
    r3d.view_distance = radius * 2.3
    space.lens = 50
    space.overlay.show_overlays = False
    space.show_gizmo = False
    space.show_region_header = space.show_region_toolbar = space.show_region_ui = False
    space.shading.color_type = "MATERIAL"
    space.shading.background_type = "VIEWPORT"
    space.shading.background_color = (0.0, 0.0, 0.0)


def compiling() -> bool:
    """True while EEVEE still compiles shaders (it draws placeholders meanwhile)."""
    running = getattr(bpy.app, "is_job_running", None)
    return bool(running and running("SHADER_COMPILATION"))


def shoot(win, area, path):
    with bpy.context.temp_override(window=win, area=area, screen=win.screen):
        bpy.ops.screen.screenshot_area(filepath=path)


def crop_square(path, size):
    """Pixels (size, size, 4) of the screenshot at ``path``: its centre square, box-filtered down."""
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)
    bpy.data.images.remove(img)
    side = min(w, h)
    y0, x0 = (h - side) // 2, (w - side) // 2
    sq = px[y0:y0 + side, x0:x0 + side]
    k = max(1, side // size)  # whole-pixel box filter, then nearest to the exact size
    sq = sq[:side // k * k, :side // k * k].reshape(side // k, k, side // k, k, 4).mean(axis=(1, 3))
    idx = (np.arange(size) * sq.shape[0] / size).astype(int)
    return sq[idx][:, idx]


def save_row(tiles, path):
    row = np.concatenate(tiles, axis=1)
    h, w = row.shape[:2]
    img = bpy.data.images.new("licvdb screenshots", w, h, alpha=False)
    img.pixels[:] = row.ravel()
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()


class Shooter:
    """Steps run from a timer (the window must draw between them): set up, then per shot set the
    shading, wait two redraws, take it; finally compose and quit."""

    def __init__(self, args):
        self.args, self.tiles, self.step = args, [], 0
        self.win, self.area, self.region, self.space = view3d()
        self.pending = list(args.shots)
        self.tmp = os.path.abspath(args.out) + ".shot.png"

    def setup(self):
        from licvdb import ops_import, preview

        obj = ops_import.import_bake(bpy.context, os.path.abspath(self.args.bake), surface_preview=True)
        self.obj = obj
        if self.args.coarsen > 0:
            mod = preview.preview_of(obj).modifiers[preview.MODIFIER]
            mod.resolution_mode = "VOXEL_SIZE"
            mod.voxel_size = self.args.coarsen * obj.licvdb.voxel_size
        t = time.time()
        tris = preview.triangle_count(bpy.context, obj)
        print(f"viewport_screenshot: preview of {obj.name}: {tris} triangles, "
              f"Volume to Mesh {time.time() - t:.2f} s")
        with bpy.context.temp_override(window=self.win, area=self.area):
            bpy.ops.screen.screen_full_area()
        self.win, self.area, self.region, self.space = view3d()
        aim(self.space, obj, [float(v) for v in self.args.view.split(",")])

    def __call__(self):
        try:
            return self.tick()
        except Exception:  # noqa: BLE001 (report and quit: a timer's exception would hang the window)
            import traceback

            traceback.print_exc()
            os._exit(1)

    def tick(self):
        self.step += 1
        if self.step == 1:
            self.setup()
            return 1.0
        if self.step % 2 == 0:  # set the next shot's shading and let it draw
            if not self.pending:
                save_row(self.tiles, os.path.abspath(self.args.out))
                os.remove(self.tmp)
                print(f"viewport_screenshot: wrote {self.args.out}")
                os._exit(0)
            shading, on = SHOTS[self.pending[0]]
            self.obj.licvdb_preview.show = on
            self.space.shading.type = shading
            self.area.tag_redraw()
            return 4.0 if shading == "MATERIAL" else 1.5  # EEVEE compiles its shaders first
        if compiling():
            return 1.0
        shoot(self.win, self.area, self.tmp)
        self.tiles.append(crop_square(self.tmp, self.args.size))
        self.pending.pop(0)
        return 0.2


def main():
    args = parse_args()
    addon_utils.enable("licvdb", default_set=True)
    bpy.app.timers.register(Shooter(args), first_interval=1.0)


main()

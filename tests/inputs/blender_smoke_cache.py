# Make a tiny Blender (mantaflow) smoke simulation cache in OpenVDB format, headless:
#   blender -b --factory-startup --python-exit-code 1 -P blender_smoke_cache.py -- OUTDIR [FRAMES] [RES]
# Quick Smoke on the default cube, domain resolution RES (default 16), frames 1..FRAMES
# (default 3), cache type "Replay" written by stepping the frames. The cache lands in
# OUTDIR/data/fluid_data_####.vdb (Blender 3.x) with grids such as `density` and `velocity`.
import os
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
if not argv:
    raise SystemExit("usage: blender -b --factory-startup -P blender_smoke_cache.py -- OUTDIR [FRAMES] [RES]")
outdir = os.path.abspath(argv[0])
frames = int(argv[1]) if len(argv) > 1 else 3
res = int(argv[2]) if len(argv) > 2 else 16
os.makedirs(outdir, exist_ok=True)

scene = bpy.context.scene
cube = bpy.data.objects["Cube"]
for o in bpy.context.view_layer.objects:
    o.select_set(o == cube)
bpy.context.view_layer.objects.active = cube
bpy.ops.object.quick_smoke()

domain = next(o for o in scene.objects
              if any(m.type == 'FLUID' and m.fluid_type == 'DOMAIN' for m in o.modifiers))
mod = next(m for m in domain.modifiers if m.type == 'FLUID')
ds = mod.domain_settings
ds.resolution_max = res
ds.cache_directory = outdir
ds.cache_type = 'REPLAY'
ds.cache_data_format = 'OPENVDB'
ds.cache_frame_start = 1
ds.cache_frame_end = frames
ds.use_noise = False
scene.frame_start = 1
scene.frame_end = frames
for f in range(1, frames + 1):
    scene.frame_set(f)

found = []
for root, _dirs, files in os.walk(outdir):
    found += [os.path.join(root, f) for f in files if f.endswith(".vdb")]
print("licvdb-smoke-cache:", len(found), "vdb files")
for f in sorted(found):
    print("  ", f)
if not found:
    raise SystemExit("no .vdb cache files were written under " + outdir)

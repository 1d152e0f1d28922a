"""Pictures of baking inside Blender (docs/blender.md): a bake from a moved and turned Volume
object (licvdb.bake_volume) and a bake seeded from a mesh (a torus; licvdb.bake_file), each
rendered in Cycles:

    blender -b --factory-startup --python-exit-code 1 -P tools/blender_studio_pictures.py -- \\
        --licvdb build/vdbexport/licvdb --out-dir docs/images [--size 480] [--samples 24]

Writes OUT_DIR/studio-bake-volume.png and OUT_DIR/studio-seeds-mesh.png; the fields and bakes go
to a temporary directory. The add-on is loaded from this checkout (blender_addon/).
"""

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "blender_addon"))

import addon_utils  # noqa: E402  (Blender's modules, importable only inside Blender)
import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_studio_pictures.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--licvdb", required=True, help="the licvdb executable to bake with")
    p.add_argument("--out-dir", required=True, help="where the two PNGs go")
    p.add_argument("--size", type=int, default=480, help="square image size in pixels [480]")
    p.add_argument("--samples", type=int, default=24, help="Cycles samples per pixel [24]")
    return p.parse_args(argv)


def licvdb(exe, *args):
    subprocess.run([exe, *map(str, args), "--quiet"], check=True)


def new_scene(exe):
    bpy.ops.wm.read_homefile(use_empty=True)
    addon_utils.enable("licvdb", default_set=True)
    os.environ["LICVDB_EXECUTABLE"] = os.path.abspath(exe)
    world = bpy.data.worlds.new("studio")
    world.color = (0.02, 0.02, 0.025)
    bpy.context.scene.world = world
    return bpy.context.scene.licvdb_bake


def frame_camera(objs, direction=Vector((0.35, -1.0, 0.45)), angle=38.0):
    """A perspective camera looking along −direction at the world boxes of objs."""
    corners = [o.matrix_world @ Vector(c) for o in objs for c in o.bound_box]
    lo = Vector([min(c[a] for c in corners) for a in range(3)])
    hi = Vector([max(c[a] for c in corners) for a in range(3)])
    center, radius = (lo + hi) / 2, (hi - lo).length / 2
    data = bpy.data.cameras.new("studio camera")
    data.angle = math.radians(angle)
    data.clip_start, data.clip_end = 1e-3, 1e4
    cam = bpy.data.objects.new("studio camera", data)
    d = direction.normalized()
    cam.location = center + d * (1.05 * radius / math.sin(data.angle / 2))
    cam.rotation_euler = (-d).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam


def emission_material(name, color):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (*color, 1.0)
    out = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


def render(path, size, samples):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    r = scene.render
    r.resolution_x = r.resolution_y = size
    r.resolution_percentage = 100
    r.filepath = path
    r.image_settings.file_format = "PNG"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    t = time.time()
    bpy.ops.render.render(write_still=True)
    print(f"blender_studio_pictures: wrote {path} ({time.time() - t:.1f} s)")


def bake_from_volume(exe, tmp, out, args):
    """A tornado field imported as a Volume object, moved, turned and scaled, baked in place."""
    s = new_scene(exe)
    field = os.path.join(tmp, "tornado.vdb")
    licvdb(exe, "field", "tornado", "--res", "40,40,40", "--out", field)
    bpy.ops.object.volume_import(filepath=field)
    src = bpy.context.active_object
    src.location, src.rotation_euler, src.scale = (1.0, 0.0, 0.5), (0.35, 0.0, 0.6), (1.3, 1.3, 1.3)
    src.hide_render = True
    bpy.context.view_layer.update()
    s.input_type, s.spot_spacing, s.spot_radius = "spots", 7.0, 1.0
    s.length, s.upsample, s.color_scalar, s.colormap = 16.0, 2, "speed", "viridis"
    assert bpy.ops.licvdb.bake_volume() == {"FINISHED"}
    obj = bpy.context.active_object
    obj.licvdb.look = "HALOS"
    frame_camera([obj])
    render(os.path.join(out, "studio-bake-volume.png"), args.size, args.samples)


def bake_seeded_from_mesh(exe, tmp, out, args):
    """An ABC field baked from its file with spots seeded on a torus (shown as a wireframe)."""
    s = new_scene(exe)
    field = os.path.join(tmp, "abc.vdb")
    licvdb(exe, "field", "abc", "--res", "32,32,32", "--out", field)
    bpy.ops.mesh.primitive_torus_add(location=(math.pi, math.pi, math.pi), rotation=(0.5, 0.3, 0.0),
                                     major_radius=1.6, minor_radius=0.35)
    torus = bpy.context.active_object
    bpy.context.view_layer.update()
    s.seed_object, s.seed_mode, s.seed_spacing = torus, "SURFACE", 0.9
    s.input_type, s.spot_radius = "spots", 1.0
    s.length, s.upsample, s.color_scalar, s.colormap = 20.0, 2, "speed", "magma"
    assert bpy.ops.licvdb.bake_file(filepath=field) == {"FINISHED"}
    obj = bpy.context.active_object
    obj.licvdb.look = "HALOS"
    wire = torus.modifiers.new("wire", "WIREFRAME")
    wire.thickness = 0.015
    torus.data.materials.append(emission_material("torus wire", (0.5, 0.55, 0.6)))
    frame_camera([obj], direction=Vector((0.6, -1.0, 0.5)), angle=30.0)
    render(os.path.join(out, "studio-seeds-mesh.png"), args.size, args.samples)


def main():
    args = parse_args()
    out = os.path.abspath(args.out_dir)
    os.makedirs(out, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="licvdb_studio_") as tmp:
        bake_from_volume(args.licvdb, tmp, out, args)
        bake_seeded_from_mesh(args.licvdb, tmp, out, args)


main()

"""The extension as users install it (Blender 4.2+), in separate Blender processes with user
folders of their own (``$BLENDER_USER_RESOURCES``):

1. ``blender --command extension validate ZIP`` accepts the zip scripts/package-addon makes;
2. ``blender --command extension install-file -r user_default -e ZIP`` installs and enables it;
3. a fresh Blender started with those user folders (not ``--factory-startup``: it would ignore
   the preferences that enable the extension) has it enabled as ``bl_ext.user_default.licvdb``
   from the user repository, finds licvdb on ``PATH`` (no ``$LICVDB_EXECUTABLE``, no build tree
   beside the extension), imports a still, a cyclic loop and an unsteady sequence through
   ``bpy.ops.licvdb.import_bake``, and they lie over the field (placement.py);
4. a small Cycles render of the still shows the volume, over the field's box and nowhere else
   (an expected failure where controls.vdb_render shows this build renders no volume).

Blender before 4.2 has no extension system: test_package.py installs the legacy zip there.
"""

import json
import os
import subprocess
import textwrap

import bpy
import numpy as np
import pytest

import placement
from conftest import licvdb_exe, run_licvdb

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODULE = "bl_ext.user_default.licvdb"
RENDER_SIZE = 48

pytestmark = pytest.mark.skipif(bpy.app.version < (4, 2, 0),
                                reason=f"Blender {bpy.app.version_string} has no extension system (4.2+); "
                                       "test_package.py installs the legacy add-on zip")


def blender(args, env, timeout=300, factory=True):
    """Run Blender (background) with ``env``; returns the finished process."""
    cmd = [bpy.app.binary_path, "-b", *(["--factory-startup"] if factory else []), *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)


def output(proc):
    return f"exit {proc.returncode}\n--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-3000:]}"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The extension zip validated and installed (enabled) into a user folder of its own; the
    environment of a user whose Blender finds licvdb on PATH."""
    tmp = tmp_path_factory.mktemp("extension")
    proc = subprocess.run([os.path.join(ROOT, "scripts", "package-addon"), str(tmp / "zips")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    zip_path = tmp / "zips" / "licvdb-blender-extension.zip"
    bindir = tmp / "bin"
    bindir.mkdir()
    os.symlink(licvdb_exe(), bindir / "licvdb")
    env = {k: v for k, v in os.environ.items() if not k.startswith("BLENDER_USER_") and k != "LICVDB_EXECUTABLE"}
    env.update(BLENDER_USER_RESOURCES=str(tmp / "user"), PATH=f"{bindir}{os.pathsep}{os.environ.get('PATH', '')}")

    validate = blender(["--command", "extension", "validate", str(zip_path)], env)
    install = blender(["--command", "extension", "install-file", "-r", "user_default", "-e", str(zip_path)], env)
    return {"dir": tmp, "zip": zip_path, "env": env, "bindir": bindir, "validate": validate, "install": install}


def test_blender_validates_the_extension_zip(installed):
    proc = installed["validate"]
    assert proc.returncode == 0, output(proc)
    assert "Success parsing" in proc.stdout or "success" in proc.stdout.lower(), output(proc)


def test_blender_installs_the_extension_zip(installed):
    proc = installed["install"]
    assert proc.returncode == 0, output(proc)
    pkg = installed["dir"] / "user" / "extensions" / "user_default" / "licvdb"
    assert (pkg / "blender_manifest.toml").is_file() and (pkg / "__init__.py").is_file(), sorted(
        str(p.relative_to(installed["dir"])) for p in (installed["dir"] / "user").rglob("*"))[:40]


@pytest.fixture(scope="module")
def field_and_bakes(tmp_path_factory):
    """A 16³ ABC field and its bakes: a still, a 3-frame cyclic loop, and a 3-frame unsteady
    sequence of a moving tornado (its own fields)."""
    d = tmp_path_factory.mktemp("extension-bakes")
    run_licvdb("field", "abc", "--res", "16,16,16", "--out", d / "abc.vdb", "--quiet")
    run_licvdb("bake", "--field", d / "abc.vdb", "--out", d / "still.vdb", "--upsample", "1", "--length", "6",
               "--quiet")
    run_licvdb("bake", "--field", d / "abc.vdb", "--out", d / "loop.vdb", "--upsample", "1", "--length", "6",
               "--frames", "3", "--quiet")
    run_licvdb("field", "tornado", "--res", "16,16,16", "--frames", "1,3", "--out", d / "t_####.vdb", "--quiet")
    run_licvdb("bake", "--field", d / "t_####.vdb", "--field-frames", "1,3", "--out", d / "seq.vdb", "--upsample",
               "1", "--length", "6", "--quiet")
    info = json.loads(run_licvdb("info", d / "abc.vdb", "--json"))
    field = next(g for g in info["grids"] if g["name"] == "velocity")
    return {"dir": d, "field_bbox": field["world_bbox"]}


# Runs in the Blender the user starts after installing: every fact the parent checks, as JSON.
IMPORT_SCRIPT = """
    import json, os, sys
    import bpy
    from mathutils import Vector
    d = sys.argv[sys.argv.index("--") + 1]
    addon = bpy.context.preferences.addons.get({module!r})
    facts = {{"enabled": sorted(bpy.context.preferences.addons.keys())}}
    import importlib
    mod = importlib.import_module({module!r})
    facts["file"] = mod.__file__
    facts["executable"] = list(mod.prefs.locate_executable()[:2])
    bpy.ops.wm.read_homefile(use_empty=True)
    objects = {{}}
    for name, path in (("still", "still.vdb"), ("loop", "loop_0002.vdb"), ("seq", "seq_0003.vdb")):
        assert bpy.ops.licvdb.import_bake(filepath=os.path.join(d, path)) == {{"FINISHED"}}, name
        obj = bpy.context.active_object
        vol = obj.data
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        corners = [ev.matrix_world @ Vector(c) for c in ev.bound_box]
        out = next(n for n in obj.active_material.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
        objects[name] = {{
            "type": obj.type, "is_bake": obj.licvdb.is_bake, "grids": obj.licvdb.grid_names,
            "is_sequence": vol.is_sequence, "frame_duration": vol.frame_duration if vol.is_sequence else 1,
            "frame_start": vol.frame_start, "sequence_mode": vol.sequence_mode,
            "linked": [l.to_socket.name for l in obj.active_material.node_tree.links if l.to_node == out],
            "lo": [min(c[a] for c in corners) for a in range(3)], "hi": [max(c[a] for c in corners) for a in range(3)],
            "voxel_size": obj.licvdb.voxel_size, "half_voxel_shift": obj.licvdb.half_voxel_shift}}
        if name != "still":
            obj.hide_render = True
    facts["objects"] = objects
    if "--render" in sys.argv:
        import math
        lo, hi = objects["still"]["lo"], objects["still"]["hi"]
        cam_data = bpy.data.cameras.new("cam")
        cam_data.type = "ORTHO"
        cam_data.ortho_scale = {scale}
        cam = bpy.data.objects.new("cam", cam_data)
        bpy.context.collection.objects.link(cam)
        cam.location = ({cx}, {cy}, hi[2] + 5.0)
        bpy.context.scene.camera = cam
        scene = bpy.context.scene
        scene.cycles.device = "CPU"
        scene.cycles.samples = 8
        scene.cycles.use_denoising = False
        scene.render.resolution_x = scene.render.resolution_y = {size}
        scene.render.resolution_percentage = 100
        scene.render.image_settings.file_format = "PNG"
        scene.render.filepath = os.path.join(d, "installed.png")
        bpy.ops.render.render(write_still=True)
        facts["render"] = scene.render.filepath
    print("FACTS " + json.dumps(facts))
"""


def run_installed(installed, field_and_bakes, *extra):
    lo, hi = field_and_bakes["field_bbox"]
    width = max(hi[0] - lo[0], hi[1] - lo[1])
    script = textwrap.dedent(IMPORT_SCRIPT.format(module=MODULE, scale=1.5 * width, cx=0.5 * (lo[0] + hi[0]),
                                                  cy=0.5 * (lo[1] + hi[1]), size=RENDER_SIZE))
    path = installed["dir"] / "import.py"
    path.write_text(script)
    # No --factory-startup: the user's preferences (written by install-file -e) enable the extension.
    proc = blender(["--python-exit-code", "1", "-P", str(path), "--", str(field_and_bakes["dir"]), *extra],
                   installed["env"], factory=False)
    assert proc.returncode == 0, output(proc)
    line = next((l for l in proc.stdout.splitlines() if l.startswith("FACTS ")), None)
    assert line, output(proc)
    return json.loads(line[len("FACTS "):])


def test_installed_extension_imports_still_loop_and_sequence(installed, field_and_bakes):
    assert installed["install"].returncode == 0, output(installed["install"])
    facts = run_installed(installed, field_and_bakes)
    assert MODULE in facts["enabled"], facts["enabled"]
    assert facts["file"].startswith(str(installed["dir"] / "user" / "extensions" / "user_default")), facts["file"]
    assert facts["executable"] == [str(installed["bindir"] / "licvdb"), "PATH"], facts["executable"]
    objs = facts["objects"]
    for name, o in objs.items():
        assert o["type"] == "VOLUME" and o["is_bake"], (name, o)
        assert o["linked"] == ["Volume"], (name, o["linked"])
        assert "density" in o["grids"].split(","), (name, o["grids"])
    assert not objs["still"]["is_sequence"]
    assert objs["loop"]["is_sequence"] and objs["loop"]["frame_duration"] == 3
    assert objs["loop"]["sequence_mode"] == "REPEAT"
    seq = objs["seq"]
    assert seq["is_sequence"] and seq["frame_duration"] == 3 and seq["sequence_mode"] == "CLIP"
    assert seq["frame_start"] == 1  # plays in step with the field's frames 1-3
    # Over the field: the voxels Cycles draws cover the field's world box (to half a voxel).
    flo, fhi = field_and_bakes["field_bbox"]
    for name in ("still", "loop"):
        o = objs[name]
        assert o["half_voxel_shift"] == placement.expected_half_voxel_shift(), (name, o)
        dlo, dhi = placement.drawn_box(o["lo"], o["hi"], o["voxel_size"])
        for a in range(3):
            assert dlo[a] == pytest.approx(flo[a], abs=0.5 * o["voxel_size"] + 1e-6), (name, a, dlo, flo)
            assert dhi[a] == pytest.approx(fhi[a], abs=0.5 * o["voxel_size"] + 1e-6), (name, a, dhi, fhi)


@pytest.mark.renders
def test_installed_extension_renders_the_volume_over_the_field(installed, field_and_bakes):
    facts = run_installed(installed, field_and_bakes, "--render")
    img = bpy.data.images.load(facts["render"], check_existing=False)
    try:
        n = RENDER_SIZE
        px = np.array(img.pixels[:], dtype=np.float32).reshape(n, n, img.channels)
    finally:
        bpy.data.images.remove(img)
    lum = 0.2126 * px[..., 0] + 0.7152 * px[..., 1] + 0.0722 * px[..., 2]
    # Where the field is in the picture: the camera is centred on it, 1.5 × its width wide.
    flo, fhi = field_and_bakes["field_bbox"]
    width = max(fhi[0] - flo[0], fhi[1] - flo[1])
    pixel = 1.5 * width / n
    cx, cy = 0.5 * (flo[0] + fhi[0]), 0.5 * (flo[1] + fhi[1])
    cols = (flo[0] - cx) / pixel + n / 2, (fhi[0] - cx) / pixel + n / 2
    rows = (flo[1] - cy) / pixel + n / 2, (fhi[1] - cy) / pixel + n / 2
    lit = lum > 0.05
    assert lit.mean() > 0.1, f"the volume is not visible: {lit.mean():.3f} of the pixels lit, max {lum.max():.3f}"
    # Centred on the field: the brightness centroid across each axis lies at the field's centre (a
    # half-voxel placement error would move it by one pixel: a pixel is half a field voxel here).
    cols_profile, rows_profile = lum.mean(axis=0), lum.mean(axis=1)  # rows from the bottom (Blender's order)
    centre = np.arange(n) + 0.5
    col_c = (centre * cols_profile).sum() / cols_profile.sum()
    row_c = (centre * rows_profile).sum() / rows_profile.sum()
    # Its extent at half the plateau's brightness is the field's box, to within a pixel (Cycles
    # interpolates the outermost voxels into their neighbours: a soft edge about a voxel wide),
    # and nothing is lit beyond a voxel outside it.
    plateau = np.percentile(lum[int(rows[0]) + 2:int(rows[1]) - 2, int(cols[0]) + 2:int(cols[1]) - 2], 90)
    r, c = np.nonzero(lum > 0.5 * plateau)
    print(f"installed extension render: centroid col {col_c:.2f}, row {row_c:.2f} (field centre {n / 2}); "
          f"half-plateau rows {r.min()}..{r.max() + 1}, cols {c.min()}..{c.max() + 1}; field rows "
          f"{rows[0]:.1f}..{rows[1]:.1f}, cols {cols[0]:.1f}..{cols[1]:.1f}; plateau {plateau:.3f}")
    assert col_c == pytest.approx(n / 2, abs=0.5) and row_c == pytest.approx(n / 2, abs=0.5), (col_c, row_c)
    assert abs(c.min() - cols[0]) <= 1.01 and abs(c.max() + 1 - cols[1]) <= 1.01, (c.min(), c.max(), cols)
    assert abs(r.min() - rows[0]) <= 1.01 and abs(r.max() + 1 - rows[1]) <= 1.01, (r.min(), r.max(), rows)
    outside = np.ones_like(lit)
    outside[max(0, int(rows[0]) - 2):int(rows[1]) + 2, max(0, int(cols[0]) - 2):int(cols[1]) + 2] = False
    assert lum[outside].max() < 0.05 * plateau, f"lit outside the field's box: {lum[outside].max():.3f}"

"""Controls: what this Blender build can do at all, found without the add-on, in a separate Blender.

Some distribution builds cannot do things the add-on's tests need, for reasons outside the
add-on (measured in Debian's builds, see docs/blender.md, "Tested versions"):

- Debian's Blender 5.2.2 renders no ``.vdb`` volume: its Cycles is built without NanoVDB, which
  Cycles 5.x needs to load any grid (its log says "0 volume octree(s)");
- Debian's Blender 4.3.2 aborts on any smoke simulation (mantaflow registers its Python module
  with ``PyImport_AppendInittab`` after Python started, fatal since Python 3.12).

One control is about the pair rather than Blender alone: a licvdb built against an older OpenVDB
than this Blender's (the host's Debian 12 build, OpenVDB 10, carried into sid by
scripts/test-modern's default mode) cannot read the .vdb files this Blender's OpenVDB writes
(OpenVDB 13 writes file format 225, which OpenVDB 10 refuses): its smoke caches and the files of
OpenVDB's Python module.

Each Blender control runs a minimal script in a child Blender started with ``--factory-startup``
(the add-on is not loaded, and an abort ends only the child): a plain volume object reading a
``.vdb`` written by OpenVDB's own Python module, rendered with an emission shader; a tiny smoke
simulation. The licvdb control runs ``licvdb info`` on a grid written by OpenVDB's Python module
(the OpenVDB of this Blender's Python and, in a distribution, of Blender itself). conftest.py
marks the tests that need the capability (``@pytest.mark.renders``, ``@pytest.mark.smoke``,
``@pytest.mark.reads_blender_vdb``) as strict expected failures when, and only when, the control
shows the build lacks it: such a test still runs (a smoke test in a child Blender, see
``run_smoke``), is reported XFAIL with the control's finding, and fails the run if it passes
(XPASS strict) or fails another way.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import textwrap
from dataclasses import dataclass

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


class BlenderAborted(Exception):
    """Blender died the way its control showed it does without the add-on."""


@dataclass
class Control:
    name: str
    works: bool
    finding: str  # what the control saw, for the report

    @property
    def reason(self) -> str:
        return f"Blender {bpy.app.version_string} ({build_kind()}): {self.finding}"


def build_kind() -> str:
    """"official build" or "distribution build" (no build hash), for messages."""
    return "distribution build" if bpy.app.build_hash in (b"Unknown", b"unknown", b"") else "official build"


def run_child(script: str, *args, timeout=300) -> subprocess.CompletedProcess:
    """Run ``script`` (Python source) in a child Blender: background, factory settings, no add-on,
    user folders of its own. Returns the finished process (never raises for its exit code)."""
    with tempfile.TemporaryDirectory(prefix="licvdb-control-") as tmp:
        path = os.path.join(tmp, "control.py")
        with open(path, "w", encoding="utf-8") as f:
            f.write(textwrap.dedent(script))
        env = {k: v for k, v in os.environ.items() if k != "LICVDB_EXECUTABLE"}
        env.update(BLENDER_USER_CONFIG=os.path.join(tmp, "config"), BLENDER_USER_SCRIPTS=os.path.join(tmp, "scripts"))
        return subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1", "-P", path,
                               "--", tmp, *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env)


def _died(proc) -> str:
    """How a child ended, for a message: its exit and the fatal line if there is one."""
    out = proc.stdout + proc.stderr
    fatal = next((l.strip() for l in out.splitlines() if "Fatal Python error" in l or "PyImport_AppendInittab" in l), "")
    how = f"signal {-proc.returncode}" if proc.returncode < 0 else f"exit {proc.returncode}"
    return f"{how}{': ' + fatal if fatal else ''}"


def _aborted(proc) -> bool:
    return proc.returncode != 0 and ("PyImport_AppendInittab" in proc.stdout + proc.stderr or proc.returncode < 0
                                     or proc.returncode == 134)


_cache: dict = {}

# A 16³ block of density 0.5 – 1 (voxel 1/16: world [0, 1]³) written with OpenVDB's Python
# module (pyopenvdb before OpenVDB 12, openvdb since), read by a plain volume object with an
# emission shader from the density attribute, rendered 32² from above with Cycles on the CPU.
# The values vary from voxel to voxel: OpenVDB stores a constant block as tiles, which Blender 3.4
# renders as empty (docs/blender.md).
RENDER_SCRIPT = """
    import json, os, sys
    import bpy, numpy as np
    tmp = sys.argv[sys.argv.index("--") + 1]
    try:
        import pyopenvdb as vdb
    except ImportError:
        import openvdb as vdb
    g = vdb.FloatGrid()
    i = np.arange(16, dtype=np.float32)
    block = 0.5 + 0.5 * ((i[:, None, None] + i[None, :, None] + i[None, None, :]) % 2)
    g.copyFromArray(block.astype(np.float32), ijk=(0, 0, 0), tolerance=0.0)
    g.transform = vdb.createLinearTransform(voxelSize=1.0 / 16)
    g.name = "density"
    g.gridClass = vdb.GridClass.FOG_VOLUME
    path = os.path.join(tmp, "block.vdb")
    vdb.write(path, grids=[g])

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    vol = bpy.data.volumes.new("block")
    vol.filepath = path
    assert vol.grids.load(), vol.grids.error_message
    obj = bpy.data.objects.new("block", vol)
    scene.collection.objects.link(obj)
    mat = bpy.data.materials.new("emit")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    for n in list(nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            nodes.remove(n)
    out = nodes[0]
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "density"
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (1, 1, 1, 1)
    mul = nodes.new("ShaderNodeMath")
    mul.operation = "MULTIPLY"
    mul.inputs[1].default_value = 20.0
    links.new(attr.outputs["Fac"], mul.inputs[0])
    links.new(mul.outputs["Value"], emit.inputs["Strength"])
    links.new(emit.outputs["Emission"], out.inputs["Volume"])
    vol.materials.append(mat)
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = 2.0
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.5, 0.5, 3.0)
    scene.camera = cam
    scene.world = bpy.data.worlds.new("black")
    scene.world.color = (0, 0, 0)
    if scene.world.node_tree is not None:  # 5.x: every new world has a grey Background node
        for n in scene.world.node_tree.nodes:
            if n.bl_idname == "ShaderNodeBackground":
                n.inputs["Strength"].default_value = 0.0
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 4
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = os.path.join(tmp, "block.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(scene.render.filepath)
    px = np.array(img.pixels[:], np.float32).reshape(32, 32, img.channels)
    lum = 0.2126 * px[..., 0] + 0.7152 * px[..., 1] + 0.0722 * px[..., 2]
    # The block covers the middle half of the picture (world [0, 1] of a 2-wide view).
    print("CONTROL " + json.dumps({"inside": float(lum[10:22, 10:22].mean()), "outside": float(lum[:4, :4].mean())}))
"""


def vdb_render() -> Control:
    """Does this Blender render a .vdb volume at all? (Once per session.)"""
    if "render" not in _cache:
        proc = run_child(RENDER_SCRIPT)
        line = next((l for l in proc.stdout.splitlines() if l.startswith("CONTROL ")), None)
        if proc.returncode != 0 or line is None:
            raise RuntimeError("the render control failed to run (not a finding about this Blender):\n"
                               + proc.stdout[-2000:] + proc.stderr[-2000:])
        lum = json.loads(line[len("CONTROL "):])
        octrees = next((l.strip() for l in (proc.stdout + proc.stderr).splitlines() if "volume octree" in l), "")
        works = lum["inside"] > 0.2 and lum["outside"] < 0.05
        finding = (f"a plain volume object reading a .vdb written by OpenVDB's Python module (no add-on, no "
                   f"licvdb) renders {'as expected' if works else 'as nothing'} in Cycles (mean luminance "
                   f"{lum['inside']:.3f} over the volume, {lum['outside']:.3f} outside"
                   f"{'; ' + octrees if octrees else ''})")
        if not works:
            finding = "this build renders no .vdb volume: " + finding
        _cache["render"] = Control("renders", works, finding)
        print(f"\ncontrol: {_cache['render'].reason}")
    return _cache["render"]


SMOKE_SCRIPT = """
    import os, sys
    import bpy
    tmp = sys.argv[sys.argv.index("--") + 1]
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=2)
    dom = bpy.context.active_object
    mod = dom.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "DOMAIN"
    ds = mod.domain_settings
    ds.domain_type = "GAS"
    ds.resolution_max = 8
    ds.cache_directory = os.path.join(tmp, "cache")
    ds.cache_data_format = "OPENVDB"
    ds.cache_type = "REPLAY"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3)
    flow = bpy.context.active_object
    fm = flow.modifiers.new("Fluid", "FLUID")
    fm.fluid_type = "FLOW"
    fm.flow_settings.flow_type = "SMOKE"
    for f in (1, 2):
        bpy.context.scene.frame_set(f)
    data = os.path.join(tmp, "cache", "data")
    files = sorted(os.listdir(data)) if os.path.isdir(data) else []
    bpy.data.objects.remove(dom)  # a domain left at exit aborts Blender
    bpy.data.objects.remove(flow)
    print("CONTROL", files)
    assert any(f.endswith(".vdb") for f in files), files
"""


def smoke_simulation() -> Control:
    """Can this Blender run a smoke simulation at all? (Once per session.)"""
    if "smoke" not in _cache:
        proc = run_child(SMOKE_SCRIPT)
        if proc.returncode == 0:
            control = Control("smoke", True, "a minimal smoke simulation (no add-on) writes its OpenVDB cache")
        elif _aborted(proc):
            control = Control("smoke", False, "this build aborts on any smoke simulation: a minimal one without "
                              f"the add-on ended Blender ({_died(proc)})")
        else:
            raise RuntimeError("the smoke control failed to run (not a finding about this Blender):\n"
                               + proc.stdout[-2000:] + proc.stderr[-2000:])
        _cache["smoke"] = control
        print(f"\ncontrol: {control.reason}")
    return _cache["smoke"]


def run_smoke(cache_dir) -> None:
    """Run the tests' smoke simulation (test_fluid.make_smoke) in a child Blender, where a control
    showed that it aborts Blender: raise BlenderAborted if it does, so the test is the expected
    failure; return if it does not (the control was wrong: the caller fails the test)."""
    script = f"""
        import pathlib, sys
        sys.path[:0] = [{HERE!r}, {os.path.join(ROOT, 'blender_addon')!r}]
        sys.dont_write_bytecode = True
        import bpy
        from test_fluid import make_smoke
        bpy.ops.wm.read_homefile(use_empty=True)
        make_smoke(pathlib.Path({str(cache_dir)!r}))
        for o in list(bpy.data.objects):
            bpy.data.objects.remove(o)
    """
    proc = run_child(script)
    if _aborted(proc):
        raise BlenderAborted(f"the test's smoke simulation ended a child Blender ({_died(proc)}), as the control "
                             "without the add-on did")
    if proc.returncode != 0:
        raise RuntimeError("the smoke simulation failed in a child Blender:\n" + proc.stdout[-2000:] + proc.stderr[-2000:])


def licvdb_reads_blender_vdb(licvdb: str) -> Control:
    """Does ``licvdb`` read a .vdb written by this Blender's OpenVDB? A tiny grid written with
    OpenVDB's Python module, then ``licvdb info`` on it. (Once per session.)"""
    if "reads" not in _cache:
        import numpy as np

        vdb = vdb_module()
        version = getattr(getattr(bpy.app, "openvdb", None), "version", None)
        openvdb = "OpenVDB " + ".".join(map(str, version)) if version else "OpenVDB ?"
        with tempfile.TemporaryDirectory(prefix="licvdb-control-") as tmp:
            path = os.path.join(tmp, "small.vdb")
            g = vdb.FloatGrid()
            g.name = "density"
            g.gridClass = vdb.GridClass.FOG_VOLUME
            g.copyFromArray(np.broadcast_to(0.5 + np.arange(4, dtype=np.float32)[:, None, None] / 8, (4, 4, 4)).copy(),
                            ijk=(0, 0, 0), tolerance=0.0)
            vdb.write(path, grids=[g])
            proc = subprocess.run([licvdb, "info", path, "--json"], capture_output=True, text=True, timeout=120)
        said = (proc.stderr.strip().splitlines() or [""])[0].replace(f"'{path}'", "small.vdb")
        if proc.returncode == 0:
            control = Control("reads_blender_vdb", True, f"licvdb reads a .vdb written by OpenVDB's Python module "
                              f"(this Blender's OpenVDB: {openvdb})")
        elif "file format version" in said:
            control = Control("reads_blender_vdb", False, "this licvdb cannot read the .vdb files of this Blender's "
                              f"OpenVDB ({openvdb}; it was built against an older one): `licvdb info` on a grid "
                              f"written by OpenVDB's Python module: {said}")
        else:
            raise RuntimeError(f"the licvdb read control failed to run (not a finding about this licvdb):\n"
                               f"{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
        _cache["reads"] = control
        print(f"\ncontrol: {control.reason}")
    return _cache["reads"]


def vdb_module():
    """OpenVDB's Python module: ``pyopenvdb`` (OpenVDB ≤ 11: Debian 12, trixie) or ``openvdb``
    (OpenVDB 12+: sid). The tests read and write .vdb files with it; the add-on does not."""
    try:
        import pyopenvdb as vdb
    except ImportError:
        import openvdb as vdb
    return vdb

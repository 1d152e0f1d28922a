"""licvdb.bake_volume: LIC from a Volume object's velocity grid, placed and parented on the volume;
a volume sequence as one unsteady sequence in step with it; grid choice; errors; cancelling."""

import glob
import json
import math
import os

import bpy
import numpy as np
import pytest
from mathutils import Matrix, Vector

from licvdb import manifest as mf
from licvdb import ops_bake, ops_bake_volume

from conftest import run_licvdb
from bake_util import make_active, small_field, wait_until_running
from controls import vdb_module


def small_settings():
    s = bpy.context.scene.licvdb_bake
    s.length, s.upsample = 4.0, 1
    return s


def volume_object(path, name="flow"):
    vol = bpy.data.volumes.new(name)
    vol.filepath = str(path)
    obj = bpy.data.objects.new(name, vol)
    bpy.context.collection.objects.link(obj)
    return make_active(obj)


@pytest.fixture
def field(tmp_path):
    """A 16³ ABC field (vec3 grid ``velocity``) in a folder of its own, and small bake settings."""
    return small_field(tmp_path, length=4.0)


def bake_active():
    before = set(bpy.data.objects)
    assert bpy.ops.licvdb.bake_volume() == {"FINISHED"}
    new = set(bpy.data.objects) - before
    assert len(new) == 1, new
    obj = new.pop()
    assert obj is bpy.context.active_object and obj.type == "VOLUME" and obj.licvdb.is_bake
    return obj


def world_corners(obj):
    """The 8 corners of the object's (evaluated) bound box in world space, in bound_box order."""
    bpy.context.view_layer.update()
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    return [ev.matrix_world @ Vector(c) for c in ev.bound_box]


def assert_same_box(result, source, voxels=2.0):
    """The result's world box matches the source's corner by corner, within ``voxels`` output voxels
    (each corner's distance in world units, the voxel scaled by the source's largest scale)."""
    voxel = mf.read_manifest(result.licvdb.manifest).voxel_size * max(source.matrix_world.to_scale())
    rc, sc = world_corners(result), world_corners(source)
    assert (sc[6] - sc[0]).length > 10 * voxel, "the source's bound box is empty"
    for i, (r, s) in enumerate(zip(rc, sc)):
        assert (r - s).length <= voxels * voxel, (i, tuple(r), tuple(s), voxel)
    return voxel


def test_registered_with_its_panels():
    assert hasattr(bpy.ops.licvdb, "bake_volume")
    assert "LICVDB_PT_bake_volume" in dir(bpy.types) and "LICVDB_PT_volume_data" in dir(bpy.types)
    assert bpy.types.LICVDB_PT_volume_data.bl_context == "data"
    assert issubclass(ops_bake_volume.LICVDB_OT_bake_volume, ops_bake.BakeRunner)


def test_bake_volume_sits_on_the_moved_source_and_follows_it(field):
    src = volume_object(field)
    src.location = (1.0, -2.0, 0.5)
    src.rotation_euler = (0.3, -0.5, 0.9)
    src.scale = (0.5, 0.8, 1.2)
    bpy.context.view_layer.update()
    obj = bake_active()
    # Parented with an identity parent inverse: the local matrix is the import's own placement.
    assert obj.parent is src
    assert obj.matrix_parent_inverse == Matrix.Identity(4)
    assert obj.matrix_basis == Matrix.Translation(Vector(obj.licvdb.placement_shift))
    assert obj.licvdb.half_voxel_shift == any(obj.licvdb.placement_shift)
    assert_same_box(obj, src)
    # Moving, turning and scaling the source afterwards carries the result along.
    src.location = (4.0, 3.0, -1.0)
    src.rotation_euler = (-1.0, 0.2, 2.5)
    src.scale = (1.5, 1.5, 0.7)
    assert_same_box(obj, src)
    # The bake: the volume's file, its velocity grid, the scene's settings; beside the field.
    vol = obj.data
    out = bpy.path.abspath(vol.filepath)
    assert os.path.dirname(out) == str(field.parent / "licvdb") and os.path.basename(out).startswith("flow_lic_")
    man = mf.read_manifest(obj.licvdb.manifest)
    assert man.recipe["field"]["path"] == str(field) and man.recipe["field"]["grid"] == "velocity"
    assert man.recipe["lic"]["length"] == 4.0 and man.recipe["output"]["upsample"] == 1
    # What re-bake needs is remembered.
    s = obj.licvdb
    assert s.source_kind == "VOLUME" and s.source_object is src and s.source_grid == "velocity"
    assert json.loads(s.bake_settings)["length"] == 4.0
    assert not vol.is_sequence


def test_volume_sequence_bakes_one_unsteady_sequence_in_step(tmp_path):
    """Files numbered 11-13, shown by the source at scene frames 5-7 (frame_start 5, offset 10):
    the result plays the bake of file n at the same scene frame as the source shows file n."""
    d = tmp_path / "seq"
    d.mkdir()
    run_licvdb("field", "tornado", "--res", "16,16,16", "--frames", "11,13", "--out", d / "T_####.vdb", "--quiet")
    s = small_settings()
    s.color_scalar = "NONE"
    src = volume_object(d / "T_0011.vdb", "tornado")
    v = src.data
    v.is_sequence = True
    v.frame_duration, v.frame_start, v.frame_offset, v.sequence_mode = 3, 5, 10, "CLIP"
    obj = bake_active()
    r = obj.data
    assert r.is_sequence
    assert (r.frame_start, r.frame_duration, r.frame_offset, r.sequence_mode) == (5, 3, 10, "CLIP")
    man = mf.read_manifest(obj.licvdb.manifest)
    assert man.unsteady and man.frames == 3
    assert man.recipe["field"]["path"] == str(d / "T_####.vdb") and man.recipe["field"]["frames"] == [11, 13]
    base = bpy.path.abspath(r.filepath)[:-len("_0011.vdb")]
    assert bpy.path.abspath(r.filepath).endswith("_0011.vdb")
    for n in (11, 12, 13):
        assert os.path.isfile(f"{base}_{n:04d}.vdb"), n
    dg = bpy.context.evaluated_depsgraph_get()
    for f, n in ((5, 11), (6, 12), (7, 13)):
        bpy.context.scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        sg = src.evaluated_get(dg).data.grids
        rg = obj.evaluated_get(dg).data.grids
        assert sg.frame_filepath.endswith(f"T_{n:04d}.vdb"), (f, sg.frame_filepath)
        assert rg.frame_filepath == f"{base}_{n:04d}.vdb", (f, rg.frame_filepath)
    assert obj.parent is src
    bpy.context.scene.frame_set(5)  # (the funnel moves: its box grows with the frames; compare the first)
    assert_same_box(obj, src)


def test_velocity_grid_choice_and_errors(field, tmp_path):
    vdb = vdb_module()
    # A file with only a float grid: the report lists the grids found.
    g = vdb.FloatGrid()
    g.name = "density"
    g.copyFromArray(np.ones((4, 4, 4), np.float32))
    only_density = tmp_path / "density.vdb"
    vdb.write(str(only_density), grids=[g])
    volume_object(only_density, "smoke")
    with pytest.raises(RuntimeError, match=r"smoke has no velocity grid.*grids: density \(float\)"):
        bpy.ops.licvdb.bake_volume()
    # A grid chosen on the object that is not there.
    src = volume_object(field)
    src.licvdb.velocity_grid = "wind"
    with pytest.raises(RuntimeError, match=r"has no vector grid \"wind\" \(grids: velocity \(vector_float\)\)"):
        bpy.ops.licvdb.bake_volume()
    src.licvdb.velocity_grid = "velocity"
    result = bake_active()
    assert result.licvdb.source_grid == "velocity"
    # The automatic choice, by name.
    choose = ops_bake_volume.choose_velocity_grid
    assert choose({"density": "FLOAT", "v": "VECTOR_FLOAT", "vel": "VECTOR_FLOAT"}, "", "x") == "vel"
    assert choose({"wind": "VECTOR_FLOAT"}, "", "x") == "wind"
    assert choose({"vel.x": "FLOAT", "vel.y": "FLOAT", "vel.z": "FLOAT"}, "", "x") == "vel"
    with pytest.raises(ops_bake.BakeError, match="several vector grids"):
        choose({"a": "VECTOR_FLOAT", "b": "VECTOR_FLOAT"}, "", "x")
    # A missing file; a volume with no file; not a volume.
    gone = volume_object(tmp_path / "gone.vdb", "gone")
    with pytest.raises(RuntimeError, match="gone.vdb, does not exist"):
        bpy.ops.licvdb.bake_volume()
    gone.data.filepath = ""
    with pytest.raises(RuntimeError, match="has no file"):
        bpy.ops.licvdb.bake_volume()
    # A bake result is not offered as a source.
    bpy.context.view_layer.objects.active = result
    assert not bpy.ops.licvdb.bake_volume.poll()
    assert not glob.glob(str(tmp_path / "licvdb" / "*"))


def test_packed_volume_says_unpack_it(field):
    src = volume_object(field)
    bpy.ops.file.pack_all()
    assert src.data.packed_file is not None
    try:
        with pytest.raises(RuntimeError, match=r"packed into the \.blend: unpack it"):
            bpy.ops.licvdb.bake_volume()
    finally:
        bpy.ops.file.unpack_all(method="USE_ORIGINAL")  # (a packed file left at exit is reported as a leak)


def test_sequence_errors(tmp_path):
    d = tmp_path / "seq"
    d.mkdir()
    run_licvdb("field", "tornado", "--res", "8,8,8", "--frames", "1,2", "--out", d / "T_####.vdb", "--quiet")
    small_settings()
    src = volume_object(d / "T_0001.vdb", "tornado")
    src.data.is_sequence = True
    src.data.frame_duration = 3  # file 3 is not there
    with pytest.raises(RuntimeError, match=r"sequence of 3 files .* but 1 do not exist \(first: .*T_0003.vdb\)"):
        bpy.ops.licvdb.bake_volume()
    src.data.frame_duration = 2
    bpy.context.scene.licvdb_bake.loop_frames = 4
    with pytest.raises(RuntimeError, match="set Loop frames to 1"):
        bpy.ops.licvdb.bake_volume()
    assert ops_bake_volume.split_frame_number("/a/b_0012x.vdb") == ("/a/b_", "0012", "x.vdb")
    assert ops_bake_volume.split_frame_number("/a/b1/c.vdb") is None


@pytest.mark.reads_blender_vdb  # licvdb reads a .vdb written by this Blender's OpenVDB module
def test_houdini_split_velocity_grids(field, tmp_path):
    """Houdini writes velocity as three float grids vel.x, vel.y, vel.z: the add-on passes grid
    "vel" and licvdb bakes from the three."""
    vdb = vdb_module()
    src_grid = vdb.read(str(field), "velocity")
    lo, hi = src_grid.evalActiveVoxelBoundingBox()
    shape = tuple(h - l + 1 for l, h in zip(lo, hi))
    a = np.zeros(shape + (3,), np.float32)
    src_grid.copyToArray(a, ijk=lo)
    grids = []
    for i, c in enumerate("xyz"):
        g = vdb.FloatGrid()
        g.copyFromArray(np.ascontiguousarray(a[..., i]), ijk=lo)
        g.name = f"vel.{c}"
        g.transform = src_grid.transform
        grids.append(g)
    houdini = tmp_path / "houdini.vdb"
    vdb.write(str(houdini), grids=grids)
    volume_object(houdini, "pyro")
    obj = bake_active()
    man = mf.read_manifest(obj.licvdb.manifest)
    assert man.recipe["field"]["grid"] == "vel" and obj.licvdb.source_grid == "vel"
    assert man.grid("density").active_voxels > 0


def test_cancelled_volume_bake_leaves_no_files(tmp_path):
    """Esc in the modal run calls BakeJob.cancel(): licvdb stops (SIGINT) and writes nothing."""
    d = tmp_path / "flow"
    d.mkdir()
    run_licvdb("field", "abc", "--res", "48,48,48", "--out", d / "big.vdb", "--quiet")
    s = bpy.context.scene.licvdb_bake
    s.upsample, s.length, s.threads = 4, 30.0, 1
    src = volume_object(d / "big.vdb", "big")
    job, _ = ops_bake_volume.plan_volume_bake(bpy.context, src)
    job.tasks[0][1]["lic"]["engine"] = "naive"  # slow enough to be cancelled while it runs
    job.start()
    wait_until_running(job)
    job.cancel(grace=120.0)
    assert job.proc.returncode == 1, "licvdb did not stop on SIGINT"
    assert job.cancelled and job.finished
    assert os.listdir(d / "licvdb") == []
    assert sorted(os.listdir(d)) == ["big.vdb", "licvdb"]
    assert math.isfinite(job.fraction)

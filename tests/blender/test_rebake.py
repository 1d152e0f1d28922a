"""licvdb.rebake: a bake result baked again from its source with the scene's current settings, into
new files swapped into the same object (its material and the user's edits to it, transform,
parent and animation kept); errors; cancelling leaves the object and the disk as they were."""

import json
import os

import bpy
import pytest
from mathutils import Matrix, Vector

from licvdb import manifest as mf
from licvdb import ops_bake, ops_rebake

from conftest import run_licvdb
from bake_util import small_field, wait_until_running
from test_bake_volume import assert_same_box, bake_active, small_settings, volume_object


@pytest.fixture
def field(tmp_path):
    return small_field(tmp_path, length=4.0)


def user_edits(obj):
    """Edit the result as a user would: its material, its place (under a parent), an animation."""
    mat = obj.active_material
    nodes = mat.node_tree.nodes
    nodes["black absorption"].inputs["Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    note = nodes.new("ShaderNodeValue")
    note.name = "user value"
    note.outputs[0].default_value = 0.42
    obj.location = (0.25, 0.5, 0.75)
    obj.keyframe_insert("rotation_euler", frame=1)
    obj.rotation_euler = (0.0, 0.0, 1.0)
    obj.keyframe_insert("rotation_euler", frame=10)
    return mat


def assert_edits_kept(obj, mat, action=None):
    assert obj.active_material == mat and len(obj.data.materials) == 1
    nodes = obj.active_material.node_tree.nodes
    assert tuple(nodes["black absorption"].inputs["Color"].default_value) == pytest.approx((0.1, 0.2, 0.3, 1.0))
    assert nodes["user value"].outputs[0].default_value == pytest.approx(0.42)
    if action is not None:  # the same action, still animating (5.x actions have no .fcurves: play it)
        assert obj.animation_data.action == action
        for frame, z in ((10, 1.0), (1, 0.0)):
            bpy.context.scene.frame_set(frame)
            assert obj.rotation_euler.z == pytest.approx(z), frame


def rebake(obj):
    objects, volumes, materials = len(bpy.data.objects), len(bpy.data.volumes), len(bpy.data.materials)
    bpy.context.view_layer.objects.active = obj
    pointer, path = obj.as_pointer(), bpy.path.abspath(obj.data.filepath)
    assert bpy.ops.licvdb.rebake() == {"FINISHED"}
    # The same object, and nothing left over from the new import.
    assert obj.as_pointer() == pointer and bpy.context.active_object == obj
    assert (len(bpy.data.objects), len(bpy.data.volumes), len(bpy.data.materials)) == (objects, volumes, materials)
    new = bpy.path.abspath(obj.data.filepath)
    assert new != path and os.path.isfile(new)
    assert os.path.isfile(path), "the old files stay on disk"
    return new


def test_rebake_file_bake_in_place(field):
    assert bpy.ops.licvdb.bake_file(filepath=str(field)) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.licvdb.source_kind == "FILE" and obj.licvdb.source_path == str(field)
    parent = bpy.data.objects.new("rig", None)
    bpy.context.collection.objects.link(parent)
    parent.location = (3.0, 0.0, 0.0)
    obj.parent = parent
    mat = user_edits(obj)
    action = obj.animation_data.action
    bpy.context.scene.frame_set(1)
    basis = obj.matrix_basis.copy()
    name, shift = obj.name, Vector(obj.licvdb.placement_shift)
    s = bpy.context.scene.licvdb_bake
    s.length, s.seed = 7.0, 5
    new = rebake(obj)
    assert obj.name == name and obj.parent == parent
    assert obj.matrix_basis == basis and Vector(obj.licvdb.placement_shift) == shift  # same upsample, same shift
    assert_edits_kept(obj, mat, action)
    man = mf.read_manifest(obj.licvdb.manifest)
    assert new in man.files and man.recipe["lic"]["length"] == 7.0 and man.recipe["input"]["seed"] == 5
    assert json.loads(obj.licvdb.bake_settings)["length"] == 7.0
    assert obj.data.grids.load() and "density" in {g.name for g in obj.data.grids}
    assert obj.licvdb.source_kind == "FILE" and obj.licvdb.source_path == str(field)


def test_rebake_volume_sequence_in_place(tmp_path):
    """A volume bake re-baked with another upsample: the same object on its source (the half-voxel
    correction swapped for the new voxel), the sequence still in step with the source."""
    d = tmp_path / "seq"
    d.mkdir()
    run_licvdb("field", "tornado", "--res", "16,16,16", "--frames", "1,3", "--out", d / "T_####.vdb", "--quiet")
    small_settings().color_scalar = "NONE"
    src = volume_object(d / "T_0001.vdb", "tornado")
    src.data.is_sequence = True
    src.data.frame_duration, src.data.frame_start = 3, 4
    src.location, src.scale = (1.0, 2.0, 3.0), (2.0, 2.0, 2.0)
    obj = bake_active()
    mat = user_edits(obj)
    obj.animation_data_clear()  # (test_rebake_file_bake_in_place checks animation; here the box)
    obj.location, obj.rotation_euler = obj.licvdb.placement_shift, (0.0, 0.0, 0.0)
    old_files = mf.read_manifest(obj.licvdb.manifest).files
    bpy.context.scene.licvdb_bake.upsample = 2
    rebake(obj)
    assert_edits_kept(obj, mat)
    assert obj.parent is src and obj.matrix_parent_inverse == Matrix.Identity(4)
    assert obj.matrix_basis == Matrix.Translation(Vector(obj.licvdb.placement_shift))
    man = mf.read_manifest(obj.licvdb.manifest)
    assert man.recipe["output"]["upsample"] == 2 and man.frames == 3
    assert set(man.files).isdisjoint(old_files) and all(os.path.isfile(f) for f in old_files + man.files)
    r = obj.data
    assert (r.is_sequence, r.frame_start, r.frame_duration, r.frame_offset) == (True, 4, 3, 0)
    for f, n in ((4, 1), (5, 2), (6, 3)):
        bpy.context.scene.frame_set(f)
        grids = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.grids
        assert grids.frame_filepath == man.files[n - 1], (f, grids.frame_filepath)
    bpy.context.scene.frame_set(4)  # (the funnel moves: its box grows with the frames; compare the first)
    assert_same_box(obj, src)


def test_rebake_rebuilds_the_material_only_when_the_grids_change(field):
    s = bpy.context.scene.licvdb_bake
    s.color_scalar = "NONE"
    volume_object(field)
    obj = bake_active()
    mat = obj.active_material
    assert "colormap" not in mat.node_tree.nodes
    s.color_scalar = "vorticity"
    rebake(obj)
    assert obj.active_material == mat  # the same datablock, rebuilt for the colour grids
    assert "colormap" in mat.node_tree.nodes and "scalar" in obj.licvdb.grid_names.split(",")


def test_rebake_errors(field):
    # An imported bake does not know its source.
    bake = field.parent / "imported.vdb"
    run_licvdb("bake", "--field", field, "--out", bake, "--length", "4", "--quiet")
    assert bpy.ops.licvdb.import_bake(filepath=str(bake)) == {"FINISHED"}
    assert bpy.context.active_object.licvdb.source_kind == "NONE"
    assert not bpy.ops.licvdb.rebake.poll()
    # The source volume deleted.
    src = volume_object(field)
    obj = bake_active()
    bpy.data.objects.remove(src)
    bpy.context.view_layer.objects.active = obj
    with pytest.raises(RuntimeError, match="the volume .* was baked from is gone"):
        bpy.ops.licvdb.rebake()
    # The source file gone.
    assert bpy.ops.licvdb.bake_file(filepath=str(field)) == {"FINISHED"}
    os.rename(field, field.parent / "moved.vdb")
    with pytest.raises(RuntimeError, match="F.vdb does not exist"):
        bpy.ops.licvdb.rebake()


def test_cancelled_rebake_leaves_the_object_and_no_files(tmp_path):
    d = tmp_path / "flow"
    d.mkdir()
    run_licvdb("field", "abc", "--res", "48,48,48", "--out", d / "big.vdb", "--quiet")
    s = bpy.context.scene.licvdb_bake
    s.upsample, s.length, s.threads = 1, 2.0, 0
    volume_object(d / "big.vdb", "big")
    obj = bake_active()
    path = bpy.path.abspath(obj.data.filepath)
    before = sorted(os.listdir(d / "licvdb"))
    s.upsample, s.length, s.threads = 4, 30.0, 1
    job, _ = ops_rebake.plan_rebake(bpy.context, obj)
    job.tasks[0][1]["lic"]["engine"] = "naive"  # slow enough to be cancelled while it runs
    job.start()
    wait_until_running(job)
    job.cancel(grace=120.0)
    assert job.proc.returncode == 1 and job.cancelled and job.finished
    assert sorted(os.listdir(d / "licvdb")) == before
    assert bpy.path.abspath(obj.data.filepath) == path


def test_rebake_is_a_bake_runner_with_a_panel_button(field):
    assert issubclass(ops_rebake.LICVDB_OT_rebake, ops_bake.BakeRunner)
    assert "modal" not in vars(ops_rebake.LICVDB_OT_rebake)
    from test_addon import draw_panel

    volume_object(field)
    log = draw_panel(bpy.types.LICVDB_PT_bake_volume, bpy.context)
    assert ("operator", "licvdb.bake_volume") in log and ("prop", "velocity_grid") in log
    assert draw_panel(bpy.types.LICVDB_PT_volume_data, bpy.context) == log
    bake_active()
    assert not bpy.types.LICVDB_PT_bake_volume.poll(bpy.context)
    log = draw_panel(bpy.types.LICVDB_PT_look, bpy.context)
    assert ("operator", "licvdb.rebake") in log
    assert any(kind == "label" and n == "Baked from: flow" for kind, n in log)

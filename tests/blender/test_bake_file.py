"""licvdb.bake_file (File > Import > Bake LIC from flow file…): licvdb bake on a field file with the
scene's bake settings, then the import; its errors; cancelling leaves nothing."""

import glob
import os

import bpy
import pytest

from licvdb import manifest as mf
from licvdb import ops_bake, ops_bake_file

from conftest import run_licvdb
from bake_util import small_field, wait_until_running
from test_executable import clean_env  # noqa: F401 (a fixture)


@pytest.fixture
def field(tmp_path):
    """A 16³ ABC field in a folder of its own, and small bake settings."""
    return small_field(tmp_path)


def bake(path, **kw):
    before = set(bpy.data.objects)
    assert bpy.ops.licvdb.bake_file(filepath=str(path), **kw) == {"FINISHED"}
    new = set(bpy.data.objects) - before
    assert len(new) == 1, new
    obj = new.pop()
    assert obj is bpy.context.active_object and obj.type == "VOLUME" and obj.licvdb.is_bake
    return obj


def test_registered_with_its_menu_entry():
    assert hasattr(bpy.ops.licvdb, "bake_file")
    draw_funcs = [f.__name__ for f in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()]
    assert "menu_bake_file" in draw_funcs and "menu_import" in draw_funcs


def test_bake_file_bakes_beside_the_field_and_imports(field):
    obj = bake(field)
    vol = obj.data
    assert vol.grids.load()
    assert {"density", "color", "scalar"} <= {g.name for g in vol.grids}  # coloured by speed (the default)
    out = bpy.path.abspath(vol.filepath)
    assert os.path.dirname(out) == str(field.parent / "licvdb")
    assert os.path.basename(out).startswith("F_lic_") and out.endswith(".vdb")
    man = mf.read_manifest(mf.manifest_path(out))
    assert man.recipe["field"]["path"] == str(field) and man.recipe["lic"]["length"] == 6.0
    assert obj["licvdb_field"] == str(field)
    # Every bake gets a new file (Blender does not notice a .vdb overwritten in place).
    again = bake(field)
    assert bpy.path.abspath(again.data.filepath) != out
    assert len(glob.glob(str(field.parent / "licvdb" / "*.vdb"))) == 2


def test_bake_file_into_the_output_folder_as_a_loop(field, tmp_path):
    s = bpy.context.scene.licvdb_bake
    s.output_dir = str(tmp_path / "out")
    s.loop_frames = 3
    s.color_scalar = "NONE"
    obj = bake(field, grid="velocity")
    vol = obj.data
    assert vol.is_sequence and vol.frame_duration == 3 and vol.sequence_mode == "REPEAT"
    assert os.path.dirname(bpy.path.abspath(vol.filepath)) == str(tmp_path / "out")
    assert bpy.path.abspath(vol.filepath).endswith("_0001.vdb")
    assert not (field.parent / "licvdb").exists()


def test_bake_file_reports_errors_and_leaves_nothing(field, tmp_path):
    with pytest.raises(RuntimeError, match="does not exist"):
        bpy.ops.licvdb.bake_file(filepath=str(tmp_path / "nowhere.vdb"))
    # licvdb's own message for a grid the field does not have; nothing is written.
    with pytest.raises(RuntimeError, match="licvdb bake failed for F.vdb.*no_such_grid"):
        bpy.ops.licvdb.bake_file(filepath=str(field), grid="no_such_grid")
    assert not glob.glob(str(field.parent / "licvdb" / "*"))
    with pytest.raises(RuntimeError, match="no file given"):
        bpy.ops.licvdb.bake_file(filepath="")


def test_bake_file_without_licvdb_says_what_to_install(field, clean_env):  # (field first: it runs licvdb)
    with pytest.raises(RuntimeError, match="licvdb-VERSION-blender-linux-x64.zip.*Preferences > Add-ons > licvdb"):
        bpy.ops.licvdb.bake_file(filepath=str(field))


def test_cancelled_file_bake_leaves_no_files(tmp_path):
    """Esc in the modal run calls BakeJob.cancel(): licvdb stops (SIGINT) and writes nothing."""
    d = tmp_path / "flow"
    d.mkdir()
    run_licvdb("field", "abc", "--res", "48,48,48", "--out", d / "big.vdb", "--quiet")
    s = bpy.context.scene.licvdb_bake
    s.upsample, s.length, s.threads = 4, 30.0, 1
    job, _ = ops_bake_file.plan_file_bake(bpy.context, str(d / "big.vdb"))
    job.tasks[0][1]["lic"]["engine"] = "naive"  # slow enough to be cancelled while it runs
    job.start()
    wait_until_running(job)
    assert "big.vdb (1/1" in job.status()
    job.cancel(grace=120.0)
    assert job.proc.returncode == 1, "licvdb did not stop on SIGINT"
    assert job.cancelled and job.finished
    assert os.listdir(d / "licvdb") == []
    assert sorted(os.listdir(d)) == ["big.vdb", "licvdb"]


def test_bake_operators_share_the_runner():
    """One implementation of the blocking and modal runs (ops_bake.BakeRunner), not two copies."""
    for op in (ops_bake.LICVDB_OT_bake_fluid, ops_bake_file.LICVDB_OT_bake_file):
        assert issubclass(op, ops_bake.BakeRunner)
        assert "modal" not in vars(op) and "_complete" not in vars(op)

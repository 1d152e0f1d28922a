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


def numbered_sequence(tmp_path, name="flow_####.vdb", frames="1,3"):
    """A 3-file numbered sequence of a moving 16³ tornado (licvdb field --frames), small settings."""
    d = tmp_path / "seq"
    d.mkdir()
    run_licvdb("field", "tornado", "--res", "16,16,16", "--frames", frames, "--out", d / name, "--quiet")
    s = bpy.context.scene.licvdb_bake
    s.length, s.upsample, s.color_scalar = 4.0, 1, "NONE"
    return d


def test_file_sequence_found_from_any_of_its_files(tmp_path):
    d = numbered_sequence(tmp_path, "fluid_data_####.vdb", "10,12")
    (d / "fluid_data_0014.vdb").write_bytes((d / "fluid_data_0010.vdb").read_bytes())  # (not next to the run)
    (d / "fluid_data_011.vdb").write_bytes(b"")  # (other digit count: not a sibling)
    pattern = str(d / "fluid_data_####.vdb")
    for n in (10, 11, 12):
        assert ops_bake_file.file_sequence(str(d / f"fluid_data_{n:04d}.vdb")) == (pattern, [10, 11, 12])
    assert ops_bake_file.file_sequence(str(d / "fluid_data_0014.vdb")) is None  # alone
    assert ops_bake_file.file_sequence(str(tmp_path / "flow.vdb")) is None  # no number
    with pytest.raises(ops_bake.BakeError, match="lacks frame 13"):
        ops_bake_file.file_sequence(pattern)  # a pattern (a re-bake's source): every file, consecutive
    (d / "fluid_data_0014.vdb").unlink()
    assert ops_bake_file.file_sequence(pattern) == (pattern, [10, 11, 12])


def test_bake_file_of_a_sequence_bakes_it_unsteady_on_its_frame_numbers(tmp_path):
    """fluid_data_0010 … 0012: one unsteady sequence, file n's bake shown at scene frame n."""
    d = numbered_sequence(tmp_path, "fluid_data_####.vdb", "10,12")
    obj = bake(d / "fluid_data_0011.vdb")  # any file of it; Sequence is on by default
    vol = obj.data
    assert vol.is_sequence and vol.sequence_mode == "CLIP"
    assert (vol.frame_start, vol.frame_duration, vol.frame_offset) == (10, 3, 9)
    man = mf.read_manifest(obj.licvdb.manifest)
    assert man.unsteady and man.frames == 3
    assert man.recipe["field"]["path"] == str(d / "fluid_data_####.vdb") and man.recipe["field"]["frames"] == [10, 12]
    base = bpy.path.abspath(vol.filepath)[:-len("_0010.vdb")]
    assert os.path.dirname(base) == str(d / "licvdb") and os.path.basename(base).startswith("fluid_data_lic_")
    for f in (10, 11, 12):
        bpy.context.scene.frame_set(f)
        grids = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.grids
        assert grids.frame_filepath == f"{base}_{f:04d}.vdb", (f, grids.frame_filepath)
    assert obj.licvdb.source_kind == "FILE" and obj.licvdb.source_path == str(d / "fluid_data_####.vdb")
    # A re-bake bakes the sequence again (its source is the pattern) into the same object.
    assert bpy.ops.licvdb.rebake() == {"FINISHED"}
    assert bpy.path.abspath(obj.data.filepath) != f"{base}_0010.vdb"
    assert (obj.data.frame_start, obj.data.frame_duration, obj.data.frame_offset) == (10, 3, 9)


def test_bake_file_sequence_off_or_a_loop(tmp_path):
    d = numbered_sequence(tmp_path)
    obj = bake(d / "flow_0002.vdb", sequence=False)  # this file alone
    assert not obj.data.is_sequence
    assert mf.read_manifest(obj.licvdb.manifest).recipe["field"]["path"] == str(d / "flow_0002.vdb")
    bpy.context.scene.licvdb_bake.loop_frames = 3
    with pytest.raises(RuntimeError, match="numbered sequence of 3 files.*set Loop frames to 1, or turn off Sequence"):
        bpy.ops.licvdb.bake_file(filepath=str(d / "flow_0001.vdb"))
    loop = bake(d / "flow_0001.vdb", sequence=False)
    assert loop.data.is_sequence and loop.data.sequence_mode == "REPEAT"


def test_file_browser_sidebar_offers_sequence_presets_and_settings(tmp_path):
    """What the operator draws beside the file browser (background mode draws no UI: a recording
    layout checks that every property shown exists)."""
    from test_addon import RecordingLayout
    d = numbered_sequence(tmp_path)
    op = ops_bake_file.LICVDB_OT_bake_file
    log = []

    class Fake:
        bl_rna = bpy.ops.licvdb.bake_file.get_rna_type()
        layout = RecordingLayout(log)
        grid, sequence = "", True
        draw_sequence = op.draw_sequence

    fake = Fake()
    for path, offered in ((d / "flow_0002.vdb", True), (tmp_path / "lone.vdb", False)):
        log.clear()
        fake.filepath = str(path)
        op.draw(fake, bpy.context)
        assert (("prop", "sequence") in log) == offered, log
        assert ("menu", "LICVDB_MT_bake_presets") in log and ("prop", "roi_scalar") in log

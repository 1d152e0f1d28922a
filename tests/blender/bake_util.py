"""What the bake tests share: a small velocity field, the active object, waiting for a running
bake (test_bake_file, test_bake_volume, test_rebake, test_fluid)."""

import time

import bpy

from conftest import run_licvdb


def small_field(tmp_path, length=6.0):
    """A 16³ ABC field (vec3 grid ``velocity``) as ``tmp_path/flow/F.vdb``, with small bake
    settings (``length`` output voxels, upsample 1); returns its path."""
    d = tmp_path / "flow"
    d.mkdir()
    path = d / "F.vdb"
    run_licvdb("field", "abc", "--res", "16,16,16", "--out", path, "--quiet")
    s = bpy.context.scene.licvdb_bake
    s.length, s.upsample = length, 1
    return path


def make_active(obj):
    """``obj`` selected, alone, and the active object."""
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def wait_until_running(job, seconds=20.0):
    """Poll a started BakeJob until licvdb reports progress (so a cancel hits a running bake)."""
    t0 = time.monotonic()
    while not [f for _, f in job.progress_seen if f > 0.0] and time.monotonic() - t0 < seconds:
        assert not job.poll(), "the bake finished before it could be cancelled; make it bigger"
        job.fraction  # noqa: B018 (reads licvdb's progress lines)
        time.sleep(0.05)

"""Fixtures for the tests that need Blender's window (see run.py)."""

import os
import subprocess

import addon_utils
import bpy
import pytest

ADDON = "licvdb"


def run_licvdb(*args):
    exe = os.environ["LICVDB_EXECUTABLE"]
    proc = subprocess.run([exe, *map(str, args)], capture_output=True, text=True)
    assert proc.returncode == 0, f"licvdb {' '.join(map(str, args))} failed ({proc.returncode}): {proc.stderr}"
    return proc.stdout


@pytest.fixture(scope="session")
def bakes(tmp_path_factory):
    d = tmp_path_factory.mktemp("bakes")
    field = d / "abc.vdb"
    run_licvdb("field", "abc", "--res", "16,16,16", "--out", field, "--quiet")
    for name in ("first", "second"):
        run_licvdb("bake", "--field", field, "--out", d / f"{name}.vdb", "--length", "4", "--quiet")
    return d


@pytest.fixture
def view3d():
    """A context override for the 3D view of the first window, as a menu click has."""
    win = bpy.context.window_manager.windows[0]
    area = next(a for a in win.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    if ADDON not in bpy.context.preferences.addons:
        addon_utils.enable(ADDON, default_set=True, handle_error=None)
    assert ADDON in bpy.context.preferences.addons
    with bpy.context.temp_override(window=win, area=area, region=region):
        for obj in [o for o in bpy.data.objects if o.type == "VOLUME"]:
            bpy.data.objects.remove(obj)
        for vol in list(bpy.data.volumes):
            bpy.data.volumes.remove(vol)
        yield

"""Fixtures for the tests that run inside Blender (see run.py), and the expected failures of
builds that a control shows cannot do what a test needs (controls.py)."""

import json
import os
import subprocess
import warnings

import addon_utils
import bpy
import pytest

import controls

ADDON = "licvdb"

#: marker → (control, the exceptions a test fails with where the control shows the build lacks it)
CAPABILITIES = {
    "renders": (controls.vdb_render, (AssertionError,)),
    "smoke": (controls.smoke_simulation, (controls.BlenderAborted,)),
    # licvdb's refusal surfaces as run_licvdb's assertion or as the bake operator's error.
    "reads_blender_vdb": (lambda: controls.licvdb_reads_blender_vdb(licvdb_exe()), (AssertionError, RuntimeError)),
}


def pytest_configure(config):
    config.addinivalue_line("markers", "renders: renders a .vdb volume in Cycles (an expected failure where "
                                       "controls.vdb_render shows this Blender renders none)")
    config.addinivalue_line("markers", "smoke: runs a smoke simulation (an expected failure where "
                                       "controls.smoke_simulation shows this Blender aborts on any)")
    config.addinivalue_line("markers", "reads_blender_vdb: licvdb reads a .vdb this Blender's OpenVDB wrote (a smoke "
                                       "cache, OpenVDB's Python module; an expected failure where "
                                       "controls.licvdb_reads_blender_vdb shows this licvdb cannot)")
    config.addinivalue_line("markers", "older_branch: forces a compat branch of an older Blender on purpose "
                                       "(its deprecation warnings are expected)")


@pytest.hookimpl(trylast=True)  # after -k/-m deselection: controls run only for tests that run
def pytest_collection_modifyitems(config, items):
    """A test that needs what this build cannot do (its control, run once without the add-on, says
    so) is a strict expected failure with the control's finding as the reason: it still runs, a
    pass fails the run (XPASS strict), and so does a failure of another kind than ``raises``."""
    for item in items:
        names = getattr(item, "fixturenames", ())
        # every test with a simulated smoke domain (test_fluid's fixture) needs smoke
        if "smoke" in names and not item.get_closest_marker("smoke"):
            item.add_marker(pytest.mark.smoke)
        # test_render's halo crossing is written by OpenVDB's Python module and read by licvdb
        if "crossing" in names and not item.get_closest_marker("reads_blender_vdb"):
            item.add_marker(pytest.mark.reads_blender_vdb)
    lacks = {}  # item → the failed controls it needs
    for marker, (control, raises) in CAPABILITIES.items():
        marked = [item for item in items if item.get_closest_marker(marker)]
        if not marked:
            continue
        found = control()
        if not found.works:
            for item in marked:
                lacks.setdefault(item, []).append((found, raises))
    # One mark per test (pytest uses only the first xfail mark): every reason, every exception.
    for item, failed in lacks.items():
        item.add_marker(pytest.mark.xfail(reason="; ".join(f.reason for f, _ in failed), strict=True,
                                          raises=tuple(e for _, r in failed for e in r)))


def licvdb_exe() -> str:
    exe = os.environ.get("LICVDB_EXECUTABLE", "")
    assert os.path.isfile(exe), f"LICVDB_EXECUTABLE={exe!r} is not a file (run through tests/blender/run.py)"
    return exe


def run_licvdb(*args, cwd=None) -> str:
    """Run licvdb, fail the test with its stderr if it fails; returns stdout."""
    proc = subprocess.run([licvdb_exe(), *map(str, args)], cwd=cwd, capture_output=True, text=True)
    assert proc.returncode == 0, f"licvdb {' '.join(map(str, args))} failed ({proc.returncode}): {proc.stderr}"
    return proc.stdout


def enable_addon():
    if ADDON not in bpy.context.preferences.addons:
        addon_utils.enable(ADDON, default_set=True, handle_error=None)
    assert ADDON in bpy.context.preferences.addons, "the licvdb add-on did not enable"


ADDON_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                         "blender_addon", "licvdb")


@pytest.fixture(autouse=True)
def no_deprecated_api_from_the_addon(request):
    """The add-on uses no Blender API that this Blender deprecates (5.x: ``use_nodes``): a
    DeprecationWarning raised from the add-on's code fails the test, except in tests that force
    an older version's branch on purpose (``@pytest.mark.older_branch``)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    if request.node.get_closest_marker("older_branch"):
        return
    ours = [f"{os.path.basename(w.filename)}:{w.lineno}: {w.message}" for w in caught
            if issubclass(w.category, DeprecationWarning) and os.path.abspath(w.filename).startswith(ADDON_DIR)]
    assert not ours, f"the add-on uses API this Blender deprecates: {ours}"


@pytest.fixture(autouse=True)
def factory_scene():
    """Every test starts from an empty factory scene with the add-on enabled."""
    bpy.ops.wm.read_homefile(use_empty=True)
    enable_addon()
    yield


@pytest.fixture(scope="session")
def bakes(tmp_path_factory):
    """A 24³ ABC field, a still bake coloured by speed, and a 4-frame cyclic loop."""
    d = tmp_path_factory.mktemp("bakes")
    field = d / "abc.vdb"
    run_licvdb("field", "abc", "--res", "24,24,24", "--out", field, "--quiet")
    still = d / "still.vdb"
    run_licvdb("bake", "--field", field, "--out", still, "--color", "speed", "--colormap", "viridis",
               "--length", "8", "--quiet")
    loop = d / "loop.vdb"
    run_licvdb("bake", "--field", field, "--out", loop, "--frames", "4", "--length", "8", "--quiet")
    info = json.loads(run_licvdb("info", field, "--json"))
    return {"dir": d, "field": field, "still": still, "loop": loop, "field_info": info}

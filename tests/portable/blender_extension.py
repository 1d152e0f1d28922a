"""The Linux extension zip as a user installs it, checked inside Blender 4.2+ on a machine with
nothing else of ours (scripts/test-portable runs it in Debian trixie's Blender 4.3 and sid's 5.2,
with a fresh HOME, no licvdb on PATH and no $LICVDB_EXECUTABLE), after

    blender -b --factory-startup --command extension install-file -r user_default \
        -e licvdb-VERSION-blender-linux-x64.zip

as

    blender -b --factory-startup --python-exit-code 1 -P tests/portable/blender_extension.py -- \\
        --field F.vdb --bake B.vdb --corrupt C.vdb --out DIR [--addon-from DIR]

F.vdb is a velocity field, B.vdb a bake by the bundle's licvdb (its manifest B.licvdb.json beside
it), C.vdb a truncated .vdb without a manifest; bakes are written into --out. The installed
extension (``bl_ext.user_default.licvdb``) is enabled here: --factory-startup leaves the user
repository in place but not the preferences that enable it. ``--addon-from DIR`` imports the
package ``licvdb`` from DIR instead (a folder holding the unpacked zip as ``licvdb/``: to try the
script in a Blender without extensions, such as 3.4).

Each check prints ``PASS NAME`` or ``FAIL NAME`` (with its traceback); the last line is
``N passed, M failed``, and the script raises (Blender exits 1) if M > 0.
"""

import argparse
import importlib
import os
import shutil
import sys
import traceback

import addon_utils
import bpy

MODULE = "bl_ext.user_default.licvdb"
CHECKS = []


def check(name):
    """Register a check: a function of the run's state that fails by raising."""
    def register(fn):
        CHECKS.append((name, fn))
        return fn
    return register


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_extension.py")
    for flag in ("--field", "--bake", "--corrupt", "--out"):
        p.add_argument(flag, required=True)
    p.add_argument("--addon-from", help="import the package licvdb from this folder instead of the extension")
    args = p.parse_args(argv)
    for name in ("field", "bake", "corrupt", "out", "addon_from"):
        if getattr(args, name):
            setattr(args, name, os.path.abspath(getattr(args, name)))
    return args


def enable(args):
    """The add-on's module, enabled: the installed extension, or the package in --addon-from."""
    name = MODULE
    if args.addon_from:
        sys.path.insert(0, args.addon_from)
        name = "licvdb"
    addon_utils.enable(name, default_set=True, handle_error=None)
    enabled = sorted(bpy.context.preferences.addons.keys())
    assert name in enabled, f"{name} did not enable (enabled: {enabled})"
    return importlib.import_module(name)


def new_objects(before):
    return [o for o in bpy.data.objects if o not in before]


@check("bundled-engine-found")
def bundled_engine_found(run):
    assert shutil.which("licvdb") is None, f"licvdb is on PATH ({shutil.which('licvdb')}): not a clean machine"
    assert not os.environ.get("LICVDB_EXECUTABLE"), "$LICVDB_EXECUTABLE is set: not a clean machine"
    path, source, tried = run.addon.prefs.locate_executable()
    print(f"  licvdb: {path} ({source}); {run.addon.prefs.executable_version(path) if path else tried}")
    assert source == "bundled engine", (path, source, tried)
    package = os.path.dirname(os.path.realpath(run.addon.__file__))
    homes = [package]
    if hasattr(bpy.utils, "extension_path_user") and run.addon.__name__.startswith("bl_ext."):
        homes.append(os.path.realpath(bpy.utils.extension_path_user(run.addon.__name__)))
    assert any(os.path.realpath(path).startswith(h + os.sep) for h in homes), (path, homes)
    assert os.access(path, os.X_OK), path


@check("import-bake")
def import_bake(run):
    before = set(bpy.data.objects)
    assert bpy.ops.licvdb.import_bake(filepath=run.args.bake) == {"FINISHED"}
    new = new_objects(before)
    assert len(new) == 1 and new[0].type == "VOLUME" and new[0].licvdb.is_bake, new
    vol = new[0].data
    assert vol.grids.load(), vol.grids.error_message
    assert "density" in {g.name for g in vol.grids}, [g.name for g in vol.grids]


@check("corrupt-refused")
def corrupt_refused(run):
    before, volumes = set(bpy.data.objects), set(bpy.data.volumes)
    try:
        bpy.ops.licvdb.import_bake(filepath=run.args.corrupt)
    except RuntimeError as e:  # the operator's error report, in background mode
        message = str(e)
    else:
        raise AssertionError("the truncated file was imported")
    print(f"  refused: {message.strip()}")
    assert "it is not an intact .vdb file" in message, message
    assert not new_objects(before) and set(bpy.data.volumes) == volumes, "something was added"


@check("bake-file")
def bake_file(run):
    s = bpy.context.scene.licvdb_bake
    s.output_dir = run.args.out
    s.length, s.upsample = 6.0, 1
    before = set(bpy.data.objects)
    assert bpy.ops.licvdb.bake_file(filepath=run.args.field) == {"FINISHED"}
    new = new_objects(before)
    assert len(new) == 1 and new[0].type == "VOLUME" and new[0].licvdb.is_bake, new
    vol = new[0].data
    assert os.path.dirname(bpy.path.abspath(vol.filepath)) == run.args.out, vol.filepath
    assert vol.grids.load(), vol.grids.error_message
    assert "density" in {g.name for g in vol.grids}, [g.name for g in vol.grids]


@check("mesh-needs-the-full-engine")
def mesh_needs_the_full_engine(run):
    # The extension's engine has no mesh module: a .vtu is refused with what to install instead.
    vtu = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                       "tests", "fuzz", "corpus", "vtu", "hex.vtu")
    assert os.path.isfile(vtu), vtu
    bpy.context.scene.licvdb_bake.output_dir = run.args.out  # (/src is read-only)
    before = set(bpy.data.objects)
    try:
        bpy.ops.licvdb.bake_file(filepath=vtu)
    except RuntimeError as e:
        message = str(e)
    else:
        raise AssertionError("the extension's engine baked a .vtu: it should have no mesh module")
    print(f"  refused: {message.strip()}")
    assert "mesh module" in message and "full licvdb bundle" in message, message
    assert not new_objects(before), "something was added"


class Run:
    def __init__(self, args, addon):
        self.args, self.addon = args, addon


def run_checks(run) -> int:
    """Run every check (all fail if the add-on did not enable); print the summary; the failures."""
    failed = 0
    for name, fn in CHECKS:
        try:
            if run.addon is None:
                raise AssertionError("the add-on did not enable (traceback above)")
            fn(run)
        except Exception:  # a failing check is reported and counted; the next one still runs
            traceback.print_exc()
            print(f"FAIL {name}", flush=True)
            failed += 1
        else:
            print(f"PASS {name}", flush=True)
    print(f"{len(CHECKS) - failed} passed, {failed} failed", flush=True)
    return failed


def main():
    args = parse_args()
    os.makedirs(args.out, exist_ok=True)
    print(f"Blender {bpy.app.version_string}, add-on from {args.addon_from or MODULE}")
    try:
        addon = enable(args)
    except Exception:  # counted below: every check fails
        traceback.print_exc()
        addon = None
    failed = run_checks(Run(args, addon))
    if failed:
        raise RuntimeError(f"{failed} check(s) of the installed extension failed")


main()

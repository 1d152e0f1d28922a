"""Finding the licvdb executable (issue 17): preferences, $LICVDB_EXECUTABLE, PATH, install
folders, a source build tree; and saying in the UI when none works. (The engine the Linux
extension carries, which comes before PATH: test_engine.py.)

The environment (PATH, HOME, LICVDB_EXECUTABLE) is changed per test with monkeypatch; the
executables are real files (a link to the licvdb under test, or a non-executable file)."""

import os

import bpy
import pytest

from licvdb import engine, prefs

from conftest import licvdb_exe
from test_addon import RecordingLayout, draw_panel

#: The licvdb under test (run.py sets $LICVDB_EXECUTABLE before pytest starts); read now, since
#: the tests unset the variable.
LICVDB = licvdb_exe()


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    """No preference, no $LICVDB_EXECUTABLE, no bundled engine (the add-on's folder is
    ``tmp_path/package``, empty), an empty PATH and HOME, no install folder or build tree: nothing
    to find until a test puts licvdb somewhere."""
    monkeypatch.delenv("LICVDB_EXECUTABLE", raising=False)
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setattr(prefs, "_EXTRA_BIN_DIRS", ("~/.local/bin",))
    monkeypatch.setattr(prefs, "_BUILD_DIRS", ())
    (tmp_path / "package").mkdir()
    monkeypatch.setattr(engine, "PACKAGE_DIR", str(tmp_path / "package"))
    p = bpy.context.preferences.addons["licvdb"].preferences
    assert p.executable == ""
    yield tmp_path
    p.executable = ""


def link_licvdb(directory):
    os.makedirs(directory, exist_ok=True)
    dst = os.path.join(directory, "licvdb")
    os.symlink(LICVDB, dst)
    return dst


def test_found_on_path(clean_env, monkeypatch):
    d = clean_env / "bin"
    exe = link_licvdb(d)
    monkeypatch.setenv("PATH", f"{clean_env / 'empty'}{os.pathsep}{d}")
    assert prefs.locate_executable()[:2] == (exe, "PATH")


def test_found_in_user_install_folder_off_path(clean_env):
    """Blender started from a desktop launcher may not have ~/.local/bin on PATH."""
    exe = link_licvdb(clean_env / "home" / ".local" / "bin")
    assert prefs.locate_executable()[:2] == (exe, "~/.local/bin")


def test_found_in_the_source_build_tree(clean_env, monkeypatch):
    """Loaded from a checkout (as these tests are), the checkout's build tree is the last resort."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(prefs.__file__))))
    trees = [d for d in ("build", "build-release", "build-blender")
             if os.access(os.path.join(root, d, "vdbexport", "licvdb"), os.X_OK)]
    assert trees, f"no licvdb built under {root} (the tests run it from there)"
    monkeypatch.setattr(prefs, "_BUILD_DIRS", (trees[0],))
    path, source, _ = prefs.locate_executable()
    assert source == "build tree" and path == os.path.join(root, trees[0], "vdbexport", "licvdb")


def test_environment_variable_before_path(clean_env, monkeypatch):
    link_licvdb(clean_env / "bin")
    monkeypatch.setenv("PATH", str(clean_env / "bin"))
    monkeypatch.setenv("LICVDB_EXECUTABLE", LICVDB)
    assert prefs.locate_executable()[:2] == (LICVDB, "$LICVDB_EXECUTABLE")


def test_preference_before_everything(clean_env, monkeypatch):
    monkeypatch.setenv("LICVDB_EXECUTABLE", LICVDB)
    exe = link_licvdb(clean_env / "chosen")
    bpy.context.preferences.addons["licvdb"].preferences.executable = exe
    assert prefs.locate_executable()[:2] == (exe, "preferences")


def test_wrong_environment_variable_is_reported_not_skipped(clean_env, monkeypatch):
    """$LICVDB_EXECUTABLE naming a missing or non-executable file is an error, not a reason to
    use some other licvdb found on PATH."""
    link_licvdb(clean_env / "bin")
    monkeypatch.setenv("PATH", str(clean_env / "bin"))
    not_exe = clean_env / "licvdb.txt"
    not_exe.write_text("")
    monkeypatch.setenv("LICVDB_EXECUTABLE", str(not_exe))
    assert prefs.find_executable() is None
    msg = prefs.missing_executable_message()
    assert f"$LICVDB_EXECUTABLE: \"{not_exe}\" is not an executable file" in msg
    assert "Preferences > Add-ons > licvdb" in msg


def test_nothing_found_says_what_was_tried(clean_env):
    assert prefs.find_executable() is None
    msg = prefs.missing_executable_message()
    for part in ("preferences: empty", "$LICVDB_EXECUTABLE: unset", "bundled engine: none in this add-on",
                 "PATH: no licvdb", "~/.local/bin", "licvdb-VERSION-blender-linux-x64.zip",
                 "Preferences > Add-ons > licvdb"):
        assert part in msg, (part, msg)


def draw_preferences(context):
    p = context.preferences.addons["licvdb"].preferences
    log = []

    class Fake:
        layout = RecordingLayout(log)
        bl_rna = p.bl_rna
        executable = p.executable
        half_voxel = p.half_voxel

    prefs.LICVDB_AddonPreferences.draw(Fake(), context)
    return [text for kind, text in log if kind == "label"]


def test_ui_says_when_licvdb_is_not_found(clean_env):
    ctx = bpy.context
    labels = draw_preferences(ctx)
    assert any("licvdb not found" in t for t in labels), labels
    assert "PATH: no licvdb" in labels
    bake_labels = [t for kind, t in draw_panel(bpy.types.LICVDB_PT_bake, ctx) if kind == "label"]
    assert "licvdb executable not found" in bake_labels


def test_ui_shows_which_licvdb_is_used(clean_env, monkeypatch):
    exe = link_licvdb(clean_env / "bin")
    monkeypatch.setenv("PATH", str(clean_env / "bin"))
    labels = draw_preferences(bpy.context)
    assert f"Using: {exe} (PATH)" in labels
    bake_labels = [t for kind, t in draw_panel(bpy.types.LICVDB_PT_bake, bpy.context) if kind == "label"]
    assert "licvdb executable not found" not in bake_labels

"""Add-on preferences: which ``licvdb`` executable the add-on runs (and its version), the
half-voxel shift, and whether imports may go ahead without licvdb's check of the files."""

import os
import shutil
import subprocess

import bpy

from . import compat, engine

#: Install folders tried after PATH: Blender started from a desktop launcher (or macOS's Finder)
#: may not have them on PATH. ``cmake --install`` defaults to /usr/local; ~/.local/bin is the usual
#: per-user prefix.
_EXTRA_BIN_DIRS = ("~/.local/bin", "/usr/local/bin", "/opt/homebrew/bin")

#: Build directories of a source checkout, tried last (only when the add-on is loaded from one;
#: an installed add-on or extension lives elsewhere and finds nothing here).
_BUILD_DIRS = ("build", "build-release", "build-blender")


def _addon_prefs(context=None):
    context = context or bpy.context
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon else None


def _is_executable(path: str) -> bool:
    return bool(path) and os.path.isfile(path) and os.access(path, os.X_OK)


def locate_executable(context=None):
    """Where ``licvdb`` is: ``(path, source, tried)``.

    In this order: the add-on preference if set, else ``$LICVDB_EXECUTABLE`` if set (either one,
    once set, is used or reported as wrong; neither falls back to a different licvdb), else the
    engine the Linux extension carries (engine.find_engine: made runnable on first use), else
    ``licvdb`` on PATH, else ~/.local/bin, /usr/local/bin, /opt/homebrew/bin, else a build tree of
    the source checkout the add-on was loaded from. ``path`` is None when nothing works;
    ``source`` names where it was found ("preferences", "$LICVDB_EXECUTABLE", "bundled engine",
    "PATH", a folder or "build tree"); ``tried`` lists what was looked at, for the message."""
    prefs = _addon_prefs(context)
    if prefs and prefs.executable:
        path = bpy.path.abspath(prefs.executable)
        if _is_executable(path):
            return path, "preferences", []
        return None, None, [f"preferences: \"{prefs.executable}\" is not an executable file"]
    env = os.environ.get("LICVDB_EXECUTABLE", "")
    if env:
        if _is_executable(env):
            return env, "$LICVDB_EXECUTABLE", []
        return None, None, [f"$LICVDB_EXECUTABLE: \"{env}\" is not an executable file"]
    tried = ["preferences: empty", "$LICVDB_EXECUTABLE: unset"]
    bundled, why = engine.find_engine()
    if bundled:
        return bundled, "bundled engine", tried
    tried.append(f"bundled engine: {why}")
    found = shutil.which("licvdb")
    if found:
        return found, "PATH", tried
    tried.append("PATH: no licvdb")
    return _locate_in_folders(tried)


def _locate_in_folders(tried):
    """The rest of locate_executable: install folders off PATH, then the checkout's build tree."""
    for d in _EXTRA_BIN_DIRS:
        p = os.path.join(os.path.expanduser(d), "licvdb")
        if _is_executable(p):
            return p, d, tried
    tried.append("not in " + ", ".join(_EXTRA_BIN_DIRS))
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for d in _BUILD_DIRS:
        p = os.path.join(root, d, "vdbexport", "licvdb")
        if _is_executable(p):
            return p, "build tree", tried
    tried.append("no build tree beside the add-on")
    return None, None, tried


def find_executable(context=None) -> str | None:
    """The licvdb executable (see locate_executable), or None if none works."""
    return locate_executable(context)[0]


def half_voxel_shift(context=None) -> bool:
    """Whether imports shift bakes by −½ voxel so Cycles renders voxel centres where OpenVDB puts
    them. Cycles' dense-texture path (builds without NanoVDB, before 5.0) maps texel t to index
    [t, t+1], so voxel i is drawn centred at i + ½ (measured on Debian's Blender 3.4.1 and 4.3.2:
    lines render half a voxel off without the shift, centred with it); its NanoVDB path (official
    builds, and every 5.x) samples at voxel centres (compat.cycles_draws_voxels_half_off)."""
    prefs = _addon_prefs(context)
    mode = prefs.half_voxel if prefs else "AUTO"
    if mode != "AUTO":
        return mode == "ON"
    return compat.cycles_draws_voxels_half_off()


def missing_executable_message(context=None) -> str:
    """Why licvdb was not found and what to do, for operator reports and the UI."""
    tried = locate_executable(context)[2]
    return ("licvdb executable not found (" + "; ".join(tried) + "): on Linux, install the extension zip that "
            "carries the engine (licvdb-VERSION-blender-linux-x64.zip); or install licvdb (its package or "
            "`cmake --install`) so it is on PATH; or set its path in Edit > Preferences > Add-ons > licvdb")


def import_unchecked_allowed(context=None) -> bool:
    """Whether the user turned on "Import without checking" (imports then go ahead without licvdb)."""
    prefs = _addon_prefs(context)
    return bool(prefs and prefs.import_unchecked)


#: ``licvdb --version`` per (path, mtime, size): the preferences draw it on every redraw.
_versions = {}


def executable_version(path: str) -> str:
    """The first line of ``licvdb --version`` ("licvdb 0.1.0"), run once per executable file."""
    try:
        st = os.stat(path)
    except OSError as e:
        return f"unknown ({e.strerror})"
    key = (path, st.st_mtime_ns, st.st_size)
    if key not in _versions:
        _versions[key] = _run_version(path)
    return _versions[key]


def _run_version(path: str) -> str:
    try:
        proc = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30,
                              stdin=subprocess.DEVNULL, env=engine.engine_env())
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"unknown (cannot run it: {e})"
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        err = proc.stderr.strip().splitlines()
        return f"unknown (--version exited {proc.returncode}" + (f": {err[0]})" if err else ")")
    return lines[0]


class LICVDB_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    executable: bpy.props.StringProperty(
        name="licvdb executable",
        description="Path to the licvdb command-line tool; empty = $LICVDB_EXECUTABLE, else the engine the Linux "
                    "extension carries, else licvdb on PATH (or in ~/.local/bin, /usr/local/bin)",
        subtype="FILE_PATH",
        default="",
    )

    half_voxel: bpy.props.EnumProperty(
        name="Half-voxel shift",
        description="Cycles before 5.0 built without NanoVDB (e.g. Debian's Blender 3.4 and 4.3) renders OpenVDB "
                    "voxel (i, j, k) half a voxel off its centre; imports shift the object back by half a voxel "
                    "to compensate",
        items=[("AUTO", "Auto", "Shift on distribution builds (no build hash, no NanoVDB) before 5.0; not on "
                                "official builds nor in 5.0+ (NanoVDB only)"),
               ("ON", "On", "Always shift by −½ voxel"),
               ("OFF", "Off", "Never shift")],
        default="AUTO",
    )

    import_unchecked: bpy.props.BoolProperty(
        name="Import without checking",
        description="Without a licvdb executable, import .vdb files unchecked (licvdb info --check cannot run). "
                    "Risky: Blender's own reader trusts the file, so a corrupt or crafted .vdb can crash Blender "
                    "and lose unsaved work",
        default=False,
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "executable")
        layout.prop(self, "half_voxel")
        layout.prop(self, "import_unchecked")
        found, source, tried = locate_executable(context)
        if found:
            col = layout.column(align=True)
            col.label(text=f"Using: {found} ({source})", icon="CHECKMARK")
            col.label(text=f"Version: {executable_version(found)}")
        else:
            col = layout.column(align=True)
            col.label(text="licvdb not found: set the path above, put licvdb on PATH, or install the Linux "
                           "extension zip that carries it", icon="ERROR")
            for line in tried:
                col.label(text=line)


classes = (LICVDB_AddonPreferences,)

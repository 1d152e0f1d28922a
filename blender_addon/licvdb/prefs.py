"""Add-on preferences: where the ``licvdb`` executable is."""

import os
import shutil

import bpy

#: Build directories of a source checkout, tried when licvdb is not on PATH.
_BUILD_DIRS = ("build", "build-release", "build-blender")


def _addon_prefs(context=None):
    context = context or bpy.context
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon else None


def find_executable(context=None) -> str | None:
    """The licvdb executable: the preference if set, else ``$LICVDB_EXECUTABLE``, else ``licvdb``
    on PATH, else a build tree next to the add-on's source checkout. None if none exists."""
    prefs = _addon_prefs(context)
    if prefs and prefs.executable:
        path = bpy.path.abspath(prefs.executable)
        return path if os.path.isfile(path) and os.access(path, os.X_OK) else None
    env = os.environ.get("LICVDB_EXECUTABLE")
    if env and os.path.isfile(env) and os.access(env, os.X_OK):
        return env
    found = shutil.which("licvdb")
    if found:
        return found
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for d in _BUILD_DIRS:
        p = os.path.join(root, d, "vdbexport", "licvdb")
        if os.path.isfile(p) and os.access(p, os.X_OK):
            return p
    return None


def half_voxel_shift(context=None) -> bool:
    """Whether imports shift bakes by −½ voxel so Cycles renders voxel centres where OpenVDB puts
    them. Cycles' dense-texture path (builds without NanoVDB) maps texel t to index [t, t+1], so
    voxel i is drawn centred at i + ½ (measured on Debian's Blender 3.4.1: lines render half a
    voxel off without the shift, centred with it); its NanoVDB path samples at voxel centres."""
    prefs = _addon_prefs(context)
    mode = prefs.half_voxel if prefs else "AUTO"
    if mode != "AUTO":
        return mode == "ON"
    return bpy.app.build_hash in (b"Unknown", b"unknown", b"")


def missing_executable_message(context=None) -> str:
    prefs = _addon_prefs(context)
    if prefs and prefs.executable:
        return (f"licvdb executable \"{prefs.executable}\" (add-on preferences) does not exist or is not "
                "executable; fix the path in Edit > Preferences > Add-ons > licvdb")
    return ("licvdb executable not found (not on PATH, $LICVDB_EXECUTABLE unset, no build tree): build it "
            "(scripts/build) and set its path in Edit > Preferences > Add-ons > licvdb")


class LICVDB_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    executable: bpy.props.StringProperty(
        name="licvdb executable",
        description="Path to the licvdb command-line tool; empty = $LICVDB_EXECUTABLE, PATH or the build tree",
        subtype="FILE_PATH",
        default="",
    )

    half_voxel: bpy.props.EnumProperty(
        name="Half-voxel shift",
        description="Cycles builds without NanoVDB (e.g. Debian's Blender 3.4) render OpenVDB voxel (i, j, k) "
                    "half a voxel off its centre; imports shift the object back by half a voxel to compensate",
        items=[("AUTO", "Auto", "Shift on distribution builds (no build hash, no NanoVDB), not on official builds"),
               ("ON", "On", "Always shift by −½ voxel"),
               ("OFF", "Off", "Never shift")],
        default="AUTO",
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "executable")
        layout.prop(self, "half_voxel")
        found = find_executable(context)
        layout.label(text=f"Using: {found}" if found else "licvdb not found: set the path above",
                     icon="CHECKMARK" if found else "ERROR")


classes = (LICVDB_AddonPreferences,)

"""Bake presets: named starting points for the scene's bake settings and the look of new bakes
(``scene.licvdb_bake``), through Blender's preset system.

The presets that come with the add-on are ``presets/bake/*.py`` inside it, read in place (an
extension must not write into its own folder, and nothing is copied): the menu lists them
together with the user's own, which *Add preset* writes (AddPresetBase) to
``bpy.utils.user_resource('SCRIPTS', path="presets/licvdb/bake")``. A preset is a Python file that
``script.execute_preset`` runs; each sets every setting in PRESET_SETTINGS, so applying one never
leaves a value of the last. Not in a preset: the seed object, the frame range, the output folder
and the thread count (where and how a bake runs, not how it looks).
"""

import os

import bpy
from bl_operators.presets import AddPresetBase

#: Below Blender's preset folders (``presets/<this>``), for the user's presets.
PRESET_SUBDIR = os.path.join("licvdb", "bake")
#: The presets that come with the add-on.
SHIPPED_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "presets", "bake")
#: The bake settings a preset sets.
PRESET_SETTINGS = ("length", "upsample", "kernel", "decay", "seed", "input_type", "spot_spacing", "spot_radius",
                   "halo_scale", "roi_scalar", "roi_range", "roi_relative", "roi_mode", "color_scalar", "colormap",
                   "loop_frames", "look_set", "look", "look_brightness", "look_absorption", "look_halo_strength")


def user_preset_dir(create: bool = False) -> str:
    """Where the user's bake presets are saved (AddPresetBase writes there)."""
    return bpy.utils.user_resource("SCRIPTS", path=os.path.join("presets", PRESET_SUBDIR), create=create)


def preset_dirs() -> list:
    """The folders the menu lists: the add-on's presets, the user's, and any other script folder's."""
    dirs = [SHIPPED_DIR, user_preset_dir(), *bpy.utils.preset_paths(PRESET_SUBDIR)]
    seen, out = set(), []
    for d in dirs:
        key = os.path.normcase(os.path.realpath(d))
        if d and os.path.isdir(d) and key not in seen:
            seen.add(key)
            out.append(d)
    return out


def shipped_presets() -> dict:
    """{display name: path} of the presets that come with the add-on."""
    return {bpy.path.display_name(f, title_case=False): os.path.join(SHIPPED_DIR, f)
            for f in sorted(os.listdir(SHIPPED_DIR)) if f.endswith(".py")}


class LICVDB_MT_bake_presets(bpy.types.Menu):
    """Bake settings and look presets: the add-on's and your own"""

    bl_idname = "LICVDB_MT_bake_presets"
    bl_label = "Bake presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "script.execute_preset"

    def draw(self, context):
        # Menu.draw_preset, with the add-on's own folder among the search paths.
        self.path_menu(preset_dirs(), self.preset_operator, filter_ext=lambda ext: ext.lower() == ".py",
                       display_name=lambda name: bpy.path.display_name(name, title_case=False))


class LICVDB_OT_bake_preset_add(AddPresetBase, bpy.types.Operator):
    """Save the scene's bake settings and look as a preset (or remove the preset last applied)"""

    bl_idname = "licvdb.bake_preset_add"
    bl_label = "Add bake preset"
    preset_menu = "LICVDB_MT_bake_presets"
    preset_subdir = PRESET_SUBDIR
    # Full paths, no preset_defines: AddPresetBase exec()s the defines and eval()s the values in
    # its own function, and from Python 3.13 (Blender 4.3+) an exec() no longer adds names that a
    # later eval() in the same function sees (PEP 667).
    preset_values = [f"bpy.context.scene.licvdb_bake.{name}" for name in PRESET_SETTINGS]

    def execute(self, context):
        if not (self.remove_active or self.remove_name):
            return super().execute(context)
        name = LICVDB_MT_bake_presets.bl_label if self.remove_active else self.name
        path = find_user_preset(name)
        if path is None:
            self.report({"WARNING"}, "the presets that come with licvdb cannot be removed"
                        if name in shipped_presets() else f"no preset {name!r} of yours to remove")
            return {"CANCELLED"}
        os.remove(path)
        LICVDB_MT_bake_presets.bl_label = "Bake presets"
        return {"FINISHED"}


def find_user_preset(name: str):
    """The path of the user's preset shown as ``name`` (not one of the add-on's), or None."""
    for d in preset_dirs()[1:]:
        for f in sorted(os.listdir(d)):
            if f.endswith(".py") and bpy.path.display_name(f, title_case=False) == name:
                return os.path.join(d, f)
    return None


def draw_preset_row(layout):
    """The preset menu with its add and remove buttons."""
    row = layout.row(align=True)
    row.menu(LICVDB_MT_bake_presets.bl_idname, text=LICVDB_MT_bake_presets.bl_label)
    row.operator(LICVDB_OT_bake_preset_add.bl_idname, text="", icon="ADD")
    row.operator(LICVDB_OT_bake_preset_add.bl_idname, text="", icon="REMOVE").remove_active = True


classes = (LICVDB_MT_bake_presets, LICVDB_OT_bake_preset_add)

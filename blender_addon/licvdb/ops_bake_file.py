"""File > Import > Bake LIC from flow file…: ``licvdb bake`` on a velocity field file, then import.

The field is any file ``licvdb bake --field`` reads (a .vdb, or .npy, .vti, .vtk, a CFD mesh…;
docs/inputs.md); the bake uses the scene's bake settings (``scene.licvdb_bake``, the licvdb
panel) and writes a new file per bake into the settings' output folder, else into a ``licvdb``
folder beside the field. Runs like licvdb.bake_fluid (ops_bake.BakeRunner): blocking from
scripts, modal with a progress bar and Esc to cancel from the menu.
"""

import os

import bpy
from bpy_extras.io_utils import ImportHelper

from . import ops_import, prefs
from .ops_bake import (BakeError, BakeJob, BakeRunner, add_seeds, make_recipe, new_bake_base, output_dir,
                       record_source, settings_dict)


def plan_file_bake(context, field_path: str, grid: str = ""):
    """(job, finish) for baking the flow field ``field_path`` (its vector grid ``grid``, "" =
    licvdb's default) with the scene's bake settings. ``finish(context)`` imports the result
    and returns the new object. Raises BakeError with what to do."""
    exe = prefs.find_executable(context)
    if exe is None:
        raise BakeError(prefs.missing_executable_message(context))
    if not os.path.exists(field_path):
        raise BakeError(f"{field_path} does not exist: choose a flow field file (.vdb or another format licvdb "
                        "reads, see `licvdb help bake`)")
    settings = context.scene.licvdb_bake
    out_dir = output_dir(settings, os.path.join(os.path.dirname(field_path), "licvdb"))
    stem = os.path.splitext(os.path.basename(os.path.normpath(field_path)))[0]
    base = new_bake_base(out_dir, stem)
    loops = settings.loop_frames
    recipe = make_recipe(settings, field_path, f"{base}.vdb", loops, grid=grid)
    add_seeds(context, settings, recipe, base)  # the result sits at the field's own coordinates
    job = BakeJob(exe, [(os.path.basename(field_path), recipe)])
    first = f"{base}_0001.vdb" if loops > 1 else f"{base}.vdb"  # a loop: OUT_0001.vdb … and one manifest
    used = settings_dict(settings)

    def finish(ctx):
        new = ops_import.import_bake(ctx, first, setup_render=True)
        new["licvdb_field"] = field_path
        record_source(new, "FILE", used, source_path=field_path, grid=grid)
        return new

    return job, finish


class LICVDB_OT_bake_file(BakeRunner, bpy.types.Operator, ImportHelper):
    """Bake LIC from a velocity field file with the scene's licvdb bake settings and import it"""

    bl_idname = "licvdb.bake_file"
    bl_label = "Bake LIC from flow file"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".vdb"
    filter_glob: bpy.props.StringProperty(default="*.vdb", options={"HIDDEN"})
    grid: bpy.props.StringProperty(
        name="Velocity grid", default="",
        description="The field's vector grid (or array) to follow; empty = licvdb's default (velocity, vel, v, "
                    "or the only vector grid)")
    # Set by invoke when it opens the file browser: the execute that follows the user's choice
    # then runs modally, as an invoke with a file would.
    interactive: bpy.props.BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    def plan(self, context):
        return plan_file_bake(context, bpy.path.abspath(self.filepath), self.grid.strip())

    def invoke(self, context, event):
        if self.properties.is_property_set("filepath"):  # a script or a drop gave the file
            return self.run_modal(context)
        self.interactive = True
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        if not self.filepath:
            self.report({"ERROR"}, "no file given: choose a flow field file")
            return {"CANCELLED"}
        if self.interactive and context.window is not None:
            return self.run_modal(context)
        return self.run_blocking(context)

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "grid")
        s = context.scene.licvdb_bake
        col = layout.column(align=True)
        col.label(text="Scene bake settings:")
        for name in ("length", "upsample", "kernel", "seed", "input_type", "spot_spacing", "spot_radius",
                     "seed_object", "seed_mode", "seed_spacing", "color_scalar", "colormap", "loop_frames",
                     "output_dir", "threads"):
            col.prop(s, name)


def menu_bake_file(self, context):
    self.layout.operator(LICVDB_OT_bake_file.bl_idname, text="Bake LIC from flow file…")


classes = (LICVDB_OT_bake_file,)

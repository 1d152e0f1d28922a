"""File > Import > Bake LIC from flow file…: ``licvdb bake`` on a velocity field file, then import.

The field is any file ``licvdb bake --field`` reads (a .vdb, or .npy, .vti, .vtk, a CFD mesh…;
docs/inputs.md); the bake uses the scene's bake settings (``scene.licvdb_bake``, the licvdb
panel) and writes a new file per bake into the settings' output folder, else into a ``licvdb``
folder beside the field. Runs like licvdb.bake_fluid (ops_bake.BakeRunner): blocking from
scripts, modal with a progress bar and Esc to cancel from the menu.

A file of a numbered sequence (flow_0001.vdb, flow_0002.vdb …; *Sequence*, on by default) bakes
the run of consecutive files around it as ONE unsteady sequence (``field.frames``, as
licvdb.bake_volume bakes a volume sequence: ops_bake.unsteady_recipe), imported so that file n's
bake plays at scene frame n. Its result remembers the ``####`` pattern as its source, so a
re-bake bakes the whole sequence again.
"""

import os
import re

import bpy
from bpy_extras.io_utils import ImportHelper

from . import ops_import, prefs, presets
from .ops_bake import (BakeError, BakeJob, BakeRunner, add_seeds, make_recipe, new_bake_base, output_dir,
                       record_source, scene_fps, settings_dict, unsteady_recipe)
from .ops_bake_volume import split_frame_number


def sibling_numbers(head: str, width: int, tail: str) -> list:
    """The sorted frame numbers of the files ``HEAD<width digits>TAIL`` on disk."""
    directory, prefix = os.path.split(head)
    pattern = re.compile(re.escape(prefix) + r"(\d{%d})" % width + re.escape(tail) + "$")
    try:
        names = os.listdir(directory or ".")
    except OSError:
        return []
    return sorted(int(m.group(1)) for m in map(pattern.match, names) if m)


def file_sequence(path: str):
    """(``####`` pattern, [consecutive frame numbers]) of the numbered sequence that ``path`` belongs
    to (flow_0001.vdb, flow_0002.vdb …: the run of consecutive numbers around its own), or None
    when it has no numbered siblings. ``path`` may be a pattern itself (a re-bake): then every
    matching file, which must be consecutive. Raises BakeError."""
    directory, name = os.path.split(path)
    hashes = re.search(r"#+", name)
    if hashes:
        head, width, tail = os.path.join(directory, name[:hashes.start()]), len(hashes.group()), name[hashes.end():]
        numbers = sibling_numbers(head, width, tail)
        if not numbers:
            raise BakeError(f"no files match {path}: were they moved? Bake the sequence again from its new place")
        gaps = sorted(set(range(numbers[0], numbers[-1] + 1)) - set(numbers))
        if gaps:
            raise BakeError(f"the sequence {path} lacks frame {gaps[0]} ({len(gaps)} missing between {numbers[0]} "
                            f"and {numbers[-1]})")
        return path, numbers
    parts = split_frame_number(path) if os.path.isfile(path) else None  # (not a case directory)
    if parts is None:
        return None
    head, digits, tail = parts
    have, n = set(sibling_numbers(head, len(digits), tail)), int(digits)
    first, last = n, n
    while first - 1 in have:
        first -= 1
    while last + 1 in have:
        last += 1
    if last == first:
        return None
    return f"{head}{'#' * len(digits)}{tail}", list(range(first, last + 1))


def plan_file_bake(context, field_path: str, grid: str = "", sequence: bool = False):
    """(job, finish) for baking the flow field ``field_path`` (its vector grid ``grid``, "" =
    licvdb's default) with the scene's bake settings; with ``sequence`` (or a ``####`` pattern as
    ``field_path``) the numbered sequence it belongs to, as one unsteady sequence whose frame n
    plays at scene frame n. ``finish(context)`` imports the result and returns the new object.
    Raises BakeError with what to do."""
    exe = prefs.find_executable(context)
    if exe is None:
        raise BakeError(prefs.missing_executable_message(context))
    seq = file_sequence(field_path) if sequence or "#" in os.path.basename(field_path) else None
    if seq is None and not os.path.exists(field_path):
        raise BakeError(f"{field_path} does not exist: choose a flow field file (.vdb or another format licvdb "
                        "reads, see `licvdb help bake`)")
    settings = context.scene.licvdb_bake
    out_dir = output_dir(settings, os.path.join(os.path.dirname(field_path), "licvdb"))
    if seq is not None:
        return _plan_sequence(context, exe, seq, out_dir, grid)
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


def _plan_sequence(context, exe: str, seq, out_dir: str, grid: str):
    """plan_file_bake for the numbered sequence ``seq`` = (pattern, frame numbers)."""
    pattern, frames = seq
    settings = context.scene.licvdb_bake
    name = os.path.basename(pattern)
    if settings.loop_frames > 1:
        raise BakeError(f"{name} is a numbered sequence of {len(frames)} files, baked as one unsteady sequence: set "
                        "Loop frames to 1, or turn off Sequence to bake the one file as a loop")
    stem = re.sub(r"#+", "", os.path.splitext(name)[0]).strip("_.- ") or "sequence"
    base = new_bake_base(out_dir, stem)
    # Velocities in world units per second (OpenVDB's convention); one frame lasts 1/fps s.
    recipe, outs = unsteady_recipe(context, settings, pattern, frames, base, scene_fps(context.scene),
                                   f"the file sequence {name}", grid=grid)
    job = BakeJob(exe, [(f"{name} frames {frames[0]}-{frames[-1]}", recipe)])
    used = settings_dict(settings)

    def finish(ctx):
        new = ops_import.import_bake(ctx, outs[0], files=outs, frame_start=frames[0], sequence_mode="CLIP",
                                     setup_render=True)
        new["licvdb_field"] = pattern
        record_source(new, "FILE", used, source_path=pattern, grid=grid)
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
    sequence: bpy.props.BoolProperty(
        name="Sequence", default=True,
        description="When the file is one of a numbered sequence (flow_0001.vdb, flow_0002.vdb …), bake the whole "
                    "sequence as one unsteady LIC sequence (frame n plays at scene frame n); off: this file alone")
    # Set by invoke when it opens the file browser: the execute that follows the user's choice
    # then runs modally, as an invoke with a file would.
    interactive: bpy.props.BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    def plan(self, context):
        return plan_file_bake(context, bpy.path.abspath(self.filepath), self.grid.strip(), self.sequence)

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
        self.draw_sequence(layout)
        s = context.scene.licvdb_bake
        col = layout.column(align=True)
        col.label(text="Scene bake settings:")
        presets.draw_preset_row(col)
        for name in ("length", "upsample", "kernel", "decay", "seed", "input_type", "spot_spacing", "spot_radius",
                     "halo_scale", "seed_object", "seed_mode", "seed_spacing", "roi_scalar", "roi_range",
                     "roi_relative", "roi_mode", "color_scalar", "colormap", "loop_frames", "look_set", "look",
                     "output_dir", "threads"):
            col.prop(s, name)

    def draw_sequence(self, layout):
        """The Sequence option, when the chosen file has numbered siblings."""
        try:
            seq = file_sequence(bpy.path.abspath(self.filepath)) if self.filepath else None
        except BakeError:
            seq = None
        if seq is None:
            return
        pattern, frames = seq
        layout.prop(self, "sequence", text=f"Sequence: {len(frames)} files, {frames[0]}-{frames[-1]}")


def menu_bake_file(self, context):
    self.layout.operator(LICVDB_OT_bake_file.bl_idname, text="Bake LIC from flow file…")


classes = (LICVDB_OT_bake_file,)

"""licvdb.bake_volume: LIC from a Volume object's velocity grid, the result placed on the volume.

The field is the volume's own file (``Volume.filepath``, relative to the .blend); its velocity
grid is the one chosen on the object (``obj.licvdb.velocity_grid``), else the first vec3 grid
named ``velocity``, ``vel`` or ``v``, else the only vec3 grid, else Houdini's split float grids
``vel.x``/``vel.y``/``vel.z`` (passed to licvdb as grid ``vel``). The bake uses the scene's bake
settings (``scene.licvdb_bake``) and runs like licvdb.bake_fluid (ops_bake.BakeRunner).

A volume *sequence* becomes one unsteady LIC sequence over the same files: Blender shows file
number ``scene frame − frame_start + 1 + frame_offset`` (the number at the end of the file name,
wrapped by ``sequence_mode``), so the field is the pattern with that number replaced by ``#``
(as many as its digits) and ``field.frames`` is ``[1 + frame_offset, frame_duration +
frame_offset]``. licvdb numbers its outputs by those frame numbers; the result gets the source's
``frame_start``, ``frame_offset`` and ``sequence_mode``, so scene frame f shows the bake of the
field file the source shows at f.

Placement: licvdb writes grids in the field file's world coordinates, which the source volume
draws in its local space. The import puts them there with an identity transform (or the −½
voxel shift, prefs.half_voxel_shift); the result is parented to the source with an identity
parent inverse, so it sits at ``source.matrix_world @ (import placement)`` and follows the source
when it moves.
"""

import os
import re

import bpy
from mathutils import Matrix

from . import ops_import, prefs, props
from .ops_bake import (BakeError, BakeJob, BakeRunner, add_seeds, make_recipe, new_bake_base, output_dir,
                       record_source, scene_fps, settings_dict, unsteady_recipe)

#: Vec3 grid names tried in order (licvdb's own default order).
VELOCITY_NAMES = ("velocity", "vel", "v")
#: Blender's names of the vector grid types licvdb reads.
VECTOR_TYPES = ("VECTOR_FLOAT", "VECTOR_DOUBLE")
#: Split velocity components (Houdini): NAME.x, NAME.y, NAME.z float grids, NAME tried in order.
SPLIT_NAMES = ("vel", "velocity", "v")
FLOAT_TYPES = ("FLOAT", "DOUBLE")


def split_frame_number(path: str):
    """(head, digits, tail) of ``path`` around the number Blender takes as the frame of a volume
    sequence (the last run of digits in the file name, before the extension); None if none."""
    directory, name = os.path.split(path)
    stem, ext = os.path.splitext(name)
    m = re.match(r"^(.*?)(\d+)(\D*)$", stem)
    if not m:
        return None
    return os.path.join(directory, m.group(1)), m.group(2), m.group(3) + ext


def sequence_frames(vol) -> list:
    """The file numbers a volume sequence shows: 1 + frame_offset … frame_duration + frame_offset."""
    return list(range(1 + vol.frame_offset, vol.frame_duration + vol.frame_offset + 1))


def volume_grids(path: str) -> dict:
    """{grid name: Blender data type} of the .vdb ``path`` (read by Blender, as the source volume
    itself is). Raises BakeError if Blender cannot read it."""
    probe = bpy.data.volumes.new("licvdb grid probe")
    try:
        probe.filepath = path
        if not probe.grids.load():
            raise BakeError(f"Blender cannot read {path}: {probe.grids.error_message or 'unknown error'}")
        return {g.name: g.data_type for g in probe.grids}
    finally:
        bpy.data.volumes.remove(probe)


def choose_velocity_grid(grids: dict, chosen: str, what: str) -> str:
    """The grid name to pass to licvdb: ``chosen`` if given (a vec3 grid, or NAME for split
    NAME.x/.y/.z), else the automatic choice (module docstring). Raises BakeError listing the
    grids found."""
    def split(name):
        return all(grids.get(f"{name}.{c}") in FLOAT_TYPES for c in "xyz")

    listing = ", ".join(f"{n} ({t.lower()})" for n, t in grids.items()) or "none"
    if chosen:
        if grids.get(chosen) in VECTOR_TYPES or split(chosen):
            return chosen
        raise BakeError(f"{what} has no vector grid \"{chosen}\" (grids: {listing}); choose another Velocity grid "
                        "or leave it empty for the automatic choice")
    for name in VELOCITY_NAMES:
        if grids.get(name) in VECTOR_TYPES:
            return name
    vectors = [n for n, t in grids.items() if t in VECTOR_TYPES]
    if len(vectors) == 1:
        return vectors[0]
    for name in SPLIT_NAMES:
        if split(name):
            return name
    if vectors:
        raise BakeError(f"{what} has several vector grids and none is named velocity, vel or v (grids: {listing}); "
                        "choose one as Velocity grid in the licvdb panel")
    raise BakeError(f"{what} has no velocity grid: no vector grid named velocity, vel or v, nor vel.x/vel.y/vel.z "
                    f"(grids: {listing})")


def volume_field(obj):
    """(field path or #### pattern, first file, [frame numbers] or None) of the Volume object
    ``obj``. Raises BakeError with what to do."""
    if obj is None or obj.type != "VOLUME":
        raise BakeError("select a Volume object (with a velocity grid) to bake LIC from")
    vol = obj.data
    if vol.packed_file is not None:
        raise BakeError(f"the file of volume {vol.name} is packed into the .blend: unpack it (File > External Data > "
                        "Unpack Resources) so that licvdb can read it")
    if not vol.filepath:
        raise BakeError(f"volume {vol.name} has no file: set its OpenVDB file (Object Data > OpenVDB File)")
    path = os.path.normpath(bpy.path.abspath(vol.filepath, library=vol.library))
    if not vol.is_sequence:
        if not os.path.isfile(path):
            raise BakeError(f"the file of volume {vol.name}, {path}, does not exist")
        return path, path, None
    parts = split_frame_number(path)
    if parts is None:
        raise BakeError(f"volume {vol.name} is a sequence but its file name {os.path.basename(path)} has no frame "
                        "number")
    head, digits, tail = parts
    frames = sequence_frames(vol)
    if not frames:
        raise BakeError(f"volume {vol.name} is a sequence of 0 frames: set its Frames")
    files = [f"{head}{n:0{len(digits)}d}{tail}" for n in frames]
    missing = [f for f in files if not os.path.isfile(f)]
    if missing:
        raise BakeError(f"volume {vol.name} is a sequence of {len(files)} files ({os.path.basename(files[0])} … "
                        f"{os.path.basename(files[-1])}) but {len(missing)} do not exist (first: {missing[0]}); "
                        "check its Frames, Offset and file")
    return f"{head}{'#' * len(digits)}{tail}", files[0], frames


def plan_volume_bake(context, obj):
    """(job, finish) for baking the Volume object ``obj`` with the scene's bake settings.
    ``finish(context)`` imports the result, parented to ``obj``, and returns it. Raises BakeError."""
    field, first_file, frames = volume_field(obj)
    exe = prefs.find_executable(context)
    if exe is None:
        raise BakeError(prefs.missing_executable_message(context))
    grid = choose_velocity_grid(volume_grids(first_file), obj.licvdb.velocity_grid.strip(), f"volume {obj.name}")
    settings = context.scene.licvdb_bake
    vol = obj.data
    out_dir = output_dir(settings, os.path.join(os.path.dirname(first_file), "licvdb"))
    base = new_bake_base(out_dir, obj.name)
    if frames is not None:
        if settings.loop_frames > 1:
            raise BakeError(f"volume {vol.name} is a sequence, baked as one unsteady sequence: set Loop frames to 1")
        # Velocities in world units per second (OpenVDB's convention); one frame lasts 1/fps s.
        recipe, outs = unsteady_recipe(context, settings, field, frames, base, scene_fps(context.scene),
                                       f"volume sequence {vol.name}", grid=grid)
        label = f"{obj.name} frames {frames[0]}-{frames[-1]}"
    else:
        recipe = make_recipe(settings, field, f"{base}.vdb", settings.loop_frames, grid=grid)
        # The result is drawn in the source's local space: world → the field's coordinates.
        add_seeds(context, settings, recipe, base, obj.matrix_world.inverted())
        label = obj.name
        outs = [f"{base}_0001.vdb" if settings.loop_frames > 1 else f"{base}.vdb"]
    job = BakeJob(exe, [(label, recipe)])
    source_name = obj.name
    used = settings_dict(settings)
    sequence = (vol.frame_start, vol.sequence_mode) if frames is not None else None

    def finish(ctx):
        if sequence is not None:
            new = ops_import.import_bake(ctx, outs[0], files=outs, frame_start=sequence[0],
                                         sequence_mode=sequence[1], setup_render=True)
        else:
            new = ops_import.import_bake(ctx, outs[0], setup_render=True)
        src = bpy.data.objects.get(source_name)
        if src is not None:
            placement = new.matrix_basis.copy()  # identity, or the −½ voxel shift
            new.parent = src
            new.matrix_parent_inverse = Matrix.Identity(4)
            new.matrix_basis = placement
            # The look scales strengths by a voxel's world size: the source's scale applies.
            sx, sy, sz = src.matrix_world.to_scale()
            new.licvdb.voxel_size = new.licvdb.voxel_size * abs(sx * sy * sz) ** (1.0 / 3.0)
            props.apply_look(new)
        new["licvdb_field"] = field
        record_source(new, "VOLUME", used, source_object=src, grid=grid)
        return new

    return job, finish


def is_source_volume(obj) -> bool:
    """Whether ``obj`` is a Volume object that can be baked from (not a licvdb result)."""
    return obj is not None and obj.type == "VOLUME" and not obj.licvdb.is_bake


class LICVDB_OT_bake_volume(BakeRunner, bpy.types.Operator):
    """Bake LIC from the active Volume object's velocity grid (a sequence: every frame, as one unsteady
    sequence) with the scene's licvdb bake settings, and import it onto the volume"""

    bl_idname = "licvdb.bake_volume"
    bl_label = "Bake LIC from volume"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return is_source_volume(context.active_object)

    def plan(self, context):
        return plan_volume_bake(context, context.active_object)


classes = (LICVDB_OT_bake_volume,)

"""licvdb.rebake: bake a result again, in place, with the scene's current bake settings.

Every bake operator records on its result what it baked (``obj.licvdb.source_kind``: FLUID,
FILE or VOLUME; ``source_object`` or ``source_path``; ``source_grid``; ``bake_settings``, the
settings it used, JSON: ops_bake.record_source). A re-bake plans the same kind of bake from that
source (plan_bake, plan_file_bake, plan_volume_bake: new file names, never a file Blender holds),
lets its finish import the new files as a temporary object, and swaps them into the original
object (swap_bake): its Volume datablock takes the new file path and sequence settings and
reloads its grids; the object keeps its name, material (with the user's edits), transform,
parent and animation. The old files stay on disk.
"""

import bpy
from mathutils import Matrix, Vector

from . import compat, ops_bake_file, ops_bake_volume, preview, props
from .ops_bake import BakeError, BakeRunner, plan_bake

#: The Volume settings a bake's import sets and a re-bake carries over.
SEQUENCE_SETTINGS = ("frame_start", "frame_duration", "frame_offset", "sequence_mode")
VELOCITY_SETTINGS = ("velocity_grid", "velocity_unit", "velocity_scale")
#: What obj.licvdb says about the bake's files (as opposed to the user's look settings).
BAKE_FACTS = ("manifest", "grid_names", "voxel_size", "colormap_points", "colormap_name", "halo_shell", "frames",
              "cyclic", "half_voxel_shift", "placement_shift", "source_kind", "source_object", "source_path",
              "source_grid", "bake_settings")


def plan_rebake(context, obj):
    """(job, finish) that bakes ``obj``'s source again with the scene's settings; ``finish``
    swaps the new files into ``obj`` and returns it. Raises BakeError with what to do."""
    if obj is None or obj.type != "VOLUME" or not obj.licvdb.is_bake:
        raise BakeError("select a licvdb bake to re-bake")
    s = obj.licvdb
    kind = s.source_kind
    if kind == "NONE":
        raise BakeError(f"{obj.name} does not say what it was baked from (imported, or baked before re-bake "
                        "existed): bake it again from its source")
    if kind == "FILE":
        job, finish = ops_bake_file.plan_file_bake(context, s.source_path, s.source_grid)
    else:
        src = s.source_object
        if src is None:
            what = "fluid domain" if kind == "FLUID" else "volume"
            raise BakeError(f"the {what} {obj.name} was baked from is gone")
        if kind == "FLUID":
            job, finish = plan_bake(context, src)
        else:
            job, finish = ops_bake_volume.plan_volume_bake(context, src)
    name = obj.name

    def swap(ctx):
        new = finish(ctx)
        old = bpy.data.objects.get(name)
        if old is None:  # the result was deleted while the bake ran: keep the new one
            return new
        swap_bake(ctx, old, new)
        return old

    return job, swap


def swap_bake(context, old, new) -> bool:
    """Move the bake imported as ``new`` into ``old`` and delete ``new`` (object, volume and
    material). ``old`` keeps its object, material, transform, parent and animation; only the
    import's own placement correction (``placement_shift``) is exchanged for the new one. The
    material is rebuilt (in the same datablock) only when the new bake's grids or colormap
    differ from the old one's; returns whether it was."""
    ov, nv = old.data, new.data
    so, sn = old.licvdb, new.licvdb
    rebuild = so.grid_names != sn.grid_names or so.colormap_points != sn.colormap_points
    # The Volume datablock: the new files, and how a sequence plays.
    ov.grids.unload()
    ov.is_sequence = nv.is_sequence
    for a in SEQUENCE_SETTINGS:
        setattr(ov, a, getattr(nv, a))
    ov.filepath = nv.filepath
    if compat.has_volume_velocity(ov):
        for a in VELOCITY_SETTINGS:
            if getattr(ov, a) != getattr(nv, a):  # (setting "" again makes Blender print an error)
                setattr(ov, a, getattr(nv, a))
    if not ov.is_sequence:
        ov.grids.load()
    ov.update_tag()
    # The placement correction (−½ output voxel where Cycles needs it) is the last factor of the
    # object's matrix: swap the old one for the new one, keep whatever the user did around it.
    old_shift, new_shift = Vector(so.placement_shift), Vector(sn.placement_shift)
    if (new_shift - old_shift).length > 0.0:
        old.matrix_basis = old.matrix_basis @ Matrix.Translation(new_shift - old_shift)
    with props.rebuild_suspended():
        for a in BAKE_FACTS:
            setattr(so, a, getattr(sn, a))
    if "licvdb_field" in new:
        old["licvdb_field"] = new["licvdb_field"]
    mats = [m for m in nv.materials if m is not None]
    preview.remove_preview(new)  # (the old object keeps its own: its modifier reads the swapped files)
    bpy.data.objects.remove(new)
    bpy.data.volumes.remove(nv)
    for m in mats:
        if m.users == 0:
            bpy.data.materials.remove(m)
    if rebuild:
        props.apply_look(old)
    for o in context.view_layer.objects:
        if o is not None:  # (4.x+: the removed object's base may linger until the view layer resyncs)
            o.select_set(False)
    if old.name in context.view_layer.objects:
        old.select_set(True)
        context.view_layer.objects.active = old
    return rebuild


class LICVDB_OT_rebake(BakeRunner, bpy.types.Operator):
    """Bake the active licvdb result again from its source with the scene's current bake settings, into
    new files that replace its volume's (the object, its material, transform and parent stay)"""

    bl_idname = "licvdb.rebake"
    bl_label = "Re-bake"
    bl_options = {"REGISTER", "UNDO"}

    done_verb = "re-baked"
    sets_look = False  # the object keeps its look (and material edits)

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return (obj is not None and obj.type == "VOLUME" and obj.licvdb.is_bake
                and obj.licvdb.source_kind != "NONE")

    def plan(self, context):
        return plan_rebake(context, context.active_object)


classes = (LICVDB_OT_rebake,)

"""File > Import > licvdb bake (.vdb): one bake, a numbered loop, or several bakes at once."""

import json
import os

import bpy
from bpy_extras.io_utils import ImportHelper

from . import manifest as mf
from mathutils import Matrix, Vector

from . import check, compat, material, prefs, preview, props
from . import grids as G


#: (brightness, line absorption) for dense (noise) bakes; sparse line bakes keep the panel's
#: defaults. The radiance of a thick dense region tends to brightness / absorption.
DENSE_LOOK = (0.6, 1.0)


class BakeImportError(Exception):
    """A bake that cannot be imported; the message says why and what to do."""


def bake_files(path: str):
    """(files in frame order, Manifest or None) for the bake that ``path`` belongs to."""
    if not os.path.isfile(path):
        raise BakeImportError(f"{path} does not exist")
    man = mf.find_manifest(path)
    if man is not None:
        missing = [f for f in man.files if not os.path.isfile(f)]
        if missing:
            raise BakeImportError(f"{man.path} lists {len(man.files)} files but {len(missing)} are missing "
                                  f"(first: {missing[0]}); re-run the bake")
        return man.files, man
    return mf.sequence_files(path), None


def import_bake(context, path: str, frame_start: int | None = None, setup_render: bool = True,
                name: str | None = None, sequence_mode: str | None = None, files=None,
                surface_preview: bool | None = None):
    """Create a Volume object for the bake ``path`` belongs to and give it the LIC look.

    Grids stay where licvdb put them in world space: the object has the identity transform, or
    a −½ voxel translation where Cycles needs it (prefs.half_voxel_shift).
    A loop (or any numbered sequence) becomes a volume sequence starting at ``frame_start``
    (default: an unsteady sequence's first frame, else the scene's start frame); cyclic bakes
    repeat forever, sequences play once (CLIP). ``files`` overrides the
    file list (frames of a sequence baked one by one). ``surface_preview``: give it the viewport's
    surface preview (preview.py); None = on in the UI, off in background mode. Raises BakeImportError.
    """
    if files:
        man = mf.find_manifest(files[0])
        if man is not None and len(man.files) != len(files):
            man.cyclic = False  # the manifest of one frame: its grids and colormap still apply
    else:
        files, man = bake_files(path)
    check.check_bake(context, files, man)  # before Blender's reader sees them (check.py)
    scene = context.scene
    first = files[0]
    stem = mf.bake_name(man.path) if man else os.path.splitext(os.path.basename(first))[0]
    vol = bpy.data.volumes.new(name or stem)
    vol.filepath = first
    # Check the first file while the volume is still a single file (a sequence's original
    # datablock has no frame until the depsgraph evaluates it).
    if not vol.grids.load():
        msg = vol.grids.error_message or "unknown error"
        bpy.data.volumes.remove(vol)
        raise BakeImportError(f"Blender cannot read {first}: {msg}")
    loaded = [g.name for g in vol.grids]
    if G.DENSITY not in loaded:
        bpy.data.volumes.remove(vol)
        raise BakeImportError(f"{first} has no \"density\" grid (grids: {', '.join(loaded) or 'none'}); "
                              "is it a licvdb bake?")
    set_velocity_grid(vol, loaded)
    n = len(files)
    if n > 1:
        vol.grids.unload()
        first_num = mf.frame_number(first) or 1
        vol.is_sequence = True
        vol.frame_duration = n
        if frame_start is None:  # an unsteady sequence plays in step with its simulation's frames
            frame_start = man.first_frame if man and man.unsteady else scene.frame_start
        vol.frame_start = frame_start
        # Blender shows file number (scene frame − frame_start + 1, wrapped by the mode) + offset.
        vol.frame_offset = first_num - 1
        cyclic = man.cyclic if man else False
        vol.sequence_mode = sequence_mode or ("REPEAT" if cyclic else "CLIP")

    obj = bpy.data.objects.new(vol.name, vol)
    context.collection.objects.link(obj)
    s = obj.licvdb
    s.is_bake = True
    s.manifest = man.path if man else ""
    s.grid_names = ",".join(man.grid_names if man else loaded)
    s.frames = n
    s.cyclic = bool(man and man.cyclic)
    s.voxel_size = (man.voxel_size if man and man.voxel_size > 0 else _voxel_size_guess(man))
    s.halo_shell = material.halo_shell_voxels(man.recipe if man else {})
    if man and man.colormap:
        s.colormap_points = json.dumps(man.colormap.points)
        s.colormap_name = man.colormap.name
    if prefs.half_voxel_shift(context):
        vs = man.grids[0].voxel_size if man and man.grids else (s.voxel_size,) * 3
        obj.matrix_world = Matrix.Translation(-0.5 * Vector(vs))
        s.half_voxel_shift = True
        s.placement_shift = -0.5 * Vector(vs)
    with props.rebuild_suspended():  # one rebuild below, not one per property
        s.look = "HALOS" if G.HALO in loaded else "LINES"
        if man and (man.recipe.get("input") or {}).get("type") == "noise":
            # Dense LIC fills its whole box: less emission and more absorption, so the streaks on
            # and just under the surface show instead of a glow summed through the volume.
            s.brightness, s.line_absorption = DENSE_LOOK
    props.apply_look(obj)
    if surface_preview is None:
        surface_preview = not bpy.app.background
    if surface_preview:
        preview.set_preview(context, obj, True)

    for o in context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    if setup_render:
        material.setup_render(scene)
    return obj


def set_velocity_grid(vol, loaded) -> bool:
    """Make a bake's ``velocity`` grid (licvdb --write-velocity: world units per second, the flow
    or how a loop's lines travel) the volume's velocity, so Cycles motion blur streaks the lines
    along the flow. Returns whether it did (False when the bake has no such grid)."""
    if G.VELOCITY not in loaded or not compat.has_volume_velocity(vol):
        return False
    vol.velocity_grid = G.VELOCITY
    vol.velocity_unit = "SECOND"
    vol.velocity_scale = 1.0
    return True


def _voxel_size_guess(man) -> float:
    if man and man.grids:
        return man.grids[0].voxel_size[0] or 1.0
    return 1.0


def import_paths(context, paths, **kw):
    """Import every distinct bake among ``paths`` (frames of one loop count once)."""
    objects, seen = [], set()
    for p in sorted(paths):
        files, man = bake_files(p)
        key = man.path if man else files[0]
        if key in seen:
            continue
        seen.add(key)
        objects.append(import_bake(context, p, **kw))
    return objects


class LICVDB_OT_import_bake(bpy.types.Operator, ImportHelper):
    """Import a licvdb bake (.vdb, or a numbered loop) as a volume with the LIC look"""

    bl_idname = "licvdb.import_bake"
    bl_label = "Import licvdb bake"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".vdb"
    filter_glob: bpy.props.StringProperty(default="*.vdb", options={"HIDDEN"})
    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    directory: bpy.props.StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    setup_render: bpy.props.BoolProperty(name="Set up render", default=True,
                                         description="Cycles, black world, volume step, no denoising without OIDN")
    surface_preview: bpy.props.BoolProperty(
        name="Surface preview", default=True,
        description="Show the lines in Solid and Material Preview as a surface (Volume to Mesh at the lines' "
                    "iso level; not in final renders). In background mode only when set")

    def invoke(self, context, event):
        # Files given by the caller (drag and drop, a script) import at once; otherwise open the
        # file browser. Not ``if self.filepath``: started from the menu, Blender restores the last
        # import's filepath, which is_property_set does not count as set (docs/blender.md).
        if self.properties.is_property_set("filepath") or (self.directory and len(self.files)):
            return self.execute(context)
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        paths = [os.path.join(self.directory, f.name) for f in self.files if f.name] if self.directory else []
        if not paths and self.filepath:
            paths = [self.filepath]
        if not paths:
            self.report({"ERROR"}, "no file given: choose a licvdb .vdb file")
            return {"CANCELLED"}
        try:
            # The checkbox in the UI; in background mode only when the caller asks for it.
            asked = self.properties.is_property_set("surface_preview") or not bpy.app.background
            surface = self.surface_preview and asked
            objects = import_paths(context, [bpy.path.abspath(p) for p in paths], setup_render=self.setup_render,
                                   surface_preview=surface)
        except (BakeImportError, mf.ManifestError, check.FileCheckError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, "imported " + ", ".join(o.name for o in objects))
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(LICVDB_OT_import_bake.bl_idname, text="licvdb bake (.vdb)")


classes = [LICVDB_OT_import_bake]

from .compat import has_file_handler  # noqa: E402 (the version guards, compat.py)

if has_file_handler():  # Blender 4.1+: drag and drop of .vdb files

    class LICVDB_FH_import_bake(bpy.types.FileHandler):
        bl_idname = "LICVDB_FH_import_bake"
        bl_label = "licvdb bake"
        bl_import_operator = "licvdb.import_bake"
        bl_file_extensions = ".vdb"

        @classmethod
        def poll_drop(cls, context):
            return context.area is not None and context.area.type == "VIEW_3D"

    classes.append(LICVDB_FH_import_bake)

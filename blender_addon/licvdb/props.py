"""Per-object look settings (``obj.licvdb``) and per-scene bake settings (``scene.licvdb_bake``)."""

import json
from contextlib import contextmanager

import bpy

from . import material, seeds


def look_of(obj) -> material.Look:
    """The Look described by ``obj.licvdb``."""
    s = obj.licvdb
    try:
        cmap = json.loads(s.colormap_points) if s.colormap_points else []
    except ValueError:
        cmap = []
    return material.Look(mode=s.look, brightness=s.brightness, line_absorption=s.line_absorption,
                         halo_strength=s.halo_strength, color_source=s.color_source, colormap=cmap,
                         voxel_size=s.voxel_size, halo_shell=s.halo_shell)


def grid_names(obj) -> list:
    return [g for g in obj.licvdb.grid_names.split(",") if g]


def lic_material(obj):
    """The object's LIC material, created (and assigned to slot 0) if missing."""
    mats = obj.data.materials
    mat = mats[0] if len(mats) and mats[0] is not None else None
    if mat is None:
        mat = bpy.data.materials.new(f"{obj.name} LIC")
        if len(mats):
            mats[0] = mat
        else:
            mats.append(mat)
    return mat


def apply_look(obj) -> dict:
    """Rebuild the object's material from its settings; returns build_lic_material's nodes."""
    return material.build_lic_material(lic_material(obj), grid_names(obj), look_of(obj))


#: > 0 while look settings are written together (see rebuild_suspended): their update callbacks
#: then do not rebuild the material once per property.
_rebuild_suspended = 0


@contextmanager
def rebuild_suspended():
    """Write several look settings with plain assignment and rebuild the material once afterwards
    (call apply_look): the update callbacks do nothing inside this block.

    This replaces dict-style writes (``s["look"] = 1``), which bypassed the callbacks by writing
    the ID-property storage directly: Blender 5.0 no longer supports that for ``bpy.props``
    properties (docs/blender.md, "Blender versions")."""
    global _rebuild_suspended
    _rebuild_suspended += 1
    try:
        yield
    finally:
        _rebuild_suspended -= 1


def _update(self, context):
    if _rebuild_suspended:
        return
    obj = self.id_data
    if isinstance(obj, bpy.types.Object) and obj.type == "VOLUME" and self.is_bake:
        apply_look(obj)


LOOKS = [("LINES", "Lines", "Emissive lines only"),
         ("HALOS", "Lines + halos", "Lines with black absorbing halos: lines behind others show gaps")]
COLOR_SOURCES = [("AUTO", "Auto", "Scalar + colour ramp if the bake has a colormap, else the color grid, else white"),
                 ("SCALAR", "Scalar + ramp", "The scalar grid through a colour ramp (lighter in memory)"),
                 ("COLOR", "Color grid", "The baked vec3 color grid"),
                 ("WHITE", "White", "Uncoloured lines")]


SOURCE_KINDS = [("NONE", "Nothing", "Imported, not baked by the add-on"),
                ("FLUID", "Fluid domain", "licvdb.bake_fluid: a smoke domain's OpenVDB cache"),
                ("FILE", "Flow file", "licvdb.bake_file: a velocity field file"),
                ("VOLUME", "Volume object", "licvdb.bake_volume: a Volume object's velocity grid")]


class LICVDB_ObjectSettings(bpy.types.PropertyGroup):
    is_bake: bpy.props.BoolProperty(name="licvdb bake", default=False)
    manifest: bpy.props.StringProperty(name="Manifest", subtype="FILE_PATH")
    grid_names: bpy.props.StringProperty(name="Grids", description="Grids of the bake, comma separated")
    voxel_size: bpy.props.FloatProperty(name="Voxel size", default=1.0, min=1e-9, precision=5)
    colormap_points: bpy.props.StringProperty(name="Colormap", description="The bake's colormap points (JSON)")
    colormap_name: bpy.props.StringProperty(name="Colormap name")
    halo_shell: bpy.props.FloatProperty(name="Halo shell", default=1.5, min=0.0,
                                        description="Output voxels from a line's edge to its halo's edge (from the recipe)")
    frames: bpy.props.IntProperty(name="Frames", default=1, min=1)
    cyclic: bpy.props.BoolProperty(name="Cyclic", default=False)
    half_voxel_shift: bpy.props.BoolProperty(name="Half-voxel shift", default=False,
                                             description="Moved by −½ voxel to correct Cycles' dense-texture offset")
    placement_shift: bpy.props.FloatVectorProperty(
        name="Placement shift", size=3, default=(0.0, 0.0, 0.0),
        description="The translation the import put last in the object's matrix (−½ output voxel where Cycles "
                    "needs it, else zero), in the object's local units; a re-bake swaps it for the new one's")

    # What a bake was made from (ops_rebake.py re-runs it): the kind of bake, its source, the
    # velocity grid asked for, and the scene's bake settings it used (JSON).
    source_kind: bpy.props.EnumProperty(name="Baked from", items=SOURCE_KINDS, default="NONE")
    source_object: bpy.props.PointerProperty(name="Source", type=bpy.types.Object,
                                             description="The fluid domain or Volume object the bake was made from")
    source_path: bpy.props.StringProperty(name="Source file", subtype="FILE_PATH",
                                          description="The flow file the bake was made from")
    source_grid: bpy.props.StringProperty(name="Source grid", description="The velocity grid the bake followed")
    bake_settings: bpy.props.StringProperty(name="Bake settings",
                                            description="The scene's bake settings the bake used (JSON)")

    # On a Volume object to bake from (licvdb.bake_volume): its velocity grid.
    velocity_grid: bpy.props.StringProperty(
        name="Velocity grid", default="",
        description="The volume's vector grid to bake LIC from; empty = automatic (velocity, vel, v, the only "
                    "vector grid, or Houdini's split vel.x/vel.y/vel.z)")

    look: bpy.props.EnumProperty(name="Look", items=LOOKS, default="LINES", update=_update)
    brightness: bpy.props.FloatProperty(name="Line brightness", default=1.0, min=0.0, soft_max=20.0,
                                        update=_update)
    line_absorption: bpy.props.FloatProperty(name="Line absorption", default=0.3, min=0.0, soft_max=5.0,
                                             update=_update,
                                             description="How much lines dim what is behind them")
    halo_strength: bpy.props.FloatProperty(name="Halo strength", default=1.5, min=0.0, soft_max=10.0,
                                           update=_update,
                                           description="Absorption of the black shell around each line")
    color_source: bpy.props.EnumProperty(name="Colour", items=COLOR_SOURCES, default="AUTO", update=_update)


SCALARS = [("NONE", "None", "Uncoloured"), ("speed", "Speed", ""), ("vorticity", "Vorticity", "|curl v|"),
           ("streamwise-vorticity", "Streamwise vorticity", ""), ("helicity", "Helicity", ""),
           ("q-criterion", "Q criterion", ""), ("lambda2", "λ2", "λ2 vortex criterion: negative in vortex cores"),
           ("density", "Smoke density", "The simulation's density grid"),
           ("temperature", "Temperature", "The simulation's temperature grid")]
ROI_SCALARS = [i for i in SCALARS if i[0] != "NONE"]
COLORMAPS = [(n, n, "") for n in ("viridis", "magma", "inferno", "cividis", "heated-object", "red-yellow",
                                  "grey-purple", "coolwarm")]


class LICVDB_BakeSettings(bpy.types.PropertyGroup):
    length: bpy.props.FloatProperty(name="Length", default=10.0, min=0.5, soft_max=100.0,
                                    description="Kernel half-length in output voxels")
    upsample: bpy.props.IntProperty(name="Upsample", default=2, min=1, max=16,
                                    description="Output voxels per simulation voxel along each axis")
    kernel: bpy.props.EnumProperty(name="Kernel", items=[("box", "Box", "Symmetric streaks"),
                                                         ("exp", "Oriented", "Tapered streamlets, bright head downstream")],
                                   default="box")
    seed: bpy.props.IntProperty(name="Seed", default=1, min=0)
    input_type: bpy.props.EnumProperty(
        name="Input", items=[("noise", "Noise", "White noise: dense, fur-like texture"),
                             ("spots", "Spots", "Sparse spots: separate lines (with halos)")],
        default="noise", description="The texture the LIC smears (a seed object always bakes spots)")
    spot_spacing: bpy.props.FloatProperty(name="Spot spacing", default=6.0, min=0.5, soft_max=64.0,
                                          description="Spots: distance between spot centres, output voxels "
                                                      "(licvdb's input.spacing)")
    spot_radius: bpy.props.FloatProperty(name="Spot radius", default=1.0, min=0.1, soft_max=8.0,
                                         description="Spots: line radius, output voxels")
    seed_object: bpy.props.PointerProperty(
        name="Seed object", type=bpy.types.Object, poll=seeds.seed_object_poll,
        description="A Mesh object whose surface or inside gives the spot centres (sampled in world space at "
                    "every bake and re-bake); empty = the usual spot distribution")
    seed_mode: bpy.props.EnumProperty(
        name="Seeds", items=[("SURFACE", "Surface", "Points spread over the mesh's faces, about Seed spacing apart"),
                             ("INSIDE", "Inside", "A lattice of pitch Seed spacing inside the closed mesh")],
        default="SURFACE")
    seed_spacing: bpy.props.FloatProperty(name="Seed spacing", default=0.5, min=1e-4, soft_max=100.0, precision=4,
                                          subtype="DISTANCE",
                                          description="Distance between seed points on or in the seed object, in "
                                                      "world units (not output voxels)")
    decay: bpy.props.FloatProperty(name="Decay", default=0.9, min=0.01, max=0.99,
                                   description="Oriented kernel: weight ratio of consecutive samples (licvdb's "
                                               "lic.decay); lower = shorter, more tapered streamlets")
    halo_scale: bpy.props.FloatProperty(name="Halo scale", default=2.0, min=1.0, soft_max=6.0,
                                        description="Spots: halo radius / line radius (licvdb's input.halo_scale)")
    roi_scalar: bpy.props.EnumProperty(
        name="Region", items=[("NONE", "Everywhere", "No region of interest")] + ROI_SCALARS, default="NONE",
        description="Region of interest: bake only where this scalar lies in the range (licvdb's roi)")
    roi_range: bpy.props.FloatVectorProperty(name="Range", size=2, default=(0.5, 1.0), soft_min=0.0,
                                             description="The scalar's range kept (Low, High)")
    roi_relative: bpy.props.BoolProperty(
        name="Fraction of top speed", default=True,
        description="Speed: the range as fractions of the field's top speed (licvdb info), so it suits any "
                    "field; off: in the field's units")
    roi_mode: bpy.props.EnumProperty(
        name="Mode", items=[("pre", "Seed inside", "Mask the input: lines start inside and leave along the flow"),
                            ("post", "Cut", "Mask the output: the texture stops at the region's edge")],
        default="pre")
    color_scalar: bpy.props.EnumProperty(name="Colour by", items=SCALARS, default="speed")
    colormap: bpy.props.EnumProperty(name="Colormap", items=COLORMAPS, default="viridis")
    loop_frames: bpy.props.IntProperty(name="Loop frames", default=1, min=1, max=1000,
                                       description="> 1: bake one simulation frame as a seamless animated loop")
    use_frame_range: bpy.props.BoolProperty(name="Frame range", default=False,
                                            description="Bake every simulation frame of a range as one coherent sequence "
                                                        "(the texture moves with the smoke)")
    range_from_cache: bpy.props.BoolProperty(
        name="Cached range", default=True,
        description="Bake the domain's cache frame range (Physics > Fluid > Cache > Frame Start/End); "
                    "off: the Start and End below")
    frame_start: bpy.props.IntProperty(name="Start", default=1, min=0)
    frame_end: bpy.props.IntProperty(name="End", default=10, min=0)
    output_dir: bpy.props.StringProperty(name="Output", subtype="DIR_PATH", default="",
                                         description="Where bakes go; empty = a licvdb folder in the fluid cache "
                                                     "(or beside the flow file)")
    threads: bpy.props.IntProperty(name="Threads", default=0, min=0, max=1024, description="0 = all cores")

    # The look a new bake gets (presets set it; a re-bake keeps its object's look instead).
    look_set: bpy.props.BoolProperty(name="Set look", default=False,
                                     description="Give new bakes this look; off: the import's choice (halos when the "
                                                 "bake has them, dense values for noise)")
    look: bpy.props.EnumProperty(name="Look", items=LOOKS, default="HALOS")
    look_brightness: bpy.props.FloatProperty(name="Line brightness", default=1.0, min=0.0, soft_max=20.0)
    look_absorption: bpy.props.FloatProperty(name="Line absorption", default=0.3, min=0.0, soft_max=5.0)
    look_halo_strength: bpy.props.FloatProperty(name="Halo strength", default=1.5, min=0.0, soft_max=10.0)


#: The look settings of new bakes (scene.licvdb_bake.look_*) → the object's look settings.
SCENE_LOOK = (("look", "look"), ("look_brightness", "brightness"), ("look_absorption", "line_absorption"),
              ("look_halo_strength", "halo_strength"))


def apply_scene_look(obj, look: dict | None):
    """Give the bake ``obj`` the look ``look`` (scene_look's dict; None: leave the import's)."""
    if not look:
        return
    s = obj.licvdb
    with rebuild_suspended():
        for name, value in look.items():
            setattr(s, name, value)
    apply_look(obj)


def scene_look(settings) -> dict | None:
    """{object look setting: value} for new bakes, or None when the settings leave the look alone."""
    if not settings.look_set:
        return None
    return {obj_name: getattr(settings, name) for name, obj_name in SCENE_LOOK}


classes = (LICVDB_ObjectSettings, LICVDB_BakeSettings)


def register_properties():
    bpy.types.Object.licvdb = bpy.props.PointerProperty(type=LICVDB_ObjectSettings)
    bpy.types.Scene.licvdb_bake = bpy.props.PointerProperty(type=LICVDB_BakeSettings)


def unregister_properties():
    del bpy.types.Scene.licvdb_bake
    del bpy.types.Object.licvdb

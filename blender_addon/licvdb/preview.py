"""A surface preview of a bake's lines for Solid and Material Preview shading.

EEVEE and the Solid view draw a volume far coarser than a bake's thin lines (a faint haze in
Solid, coarse blocks in Material Preview); only Cycles shows the streamlines. The preview is a
mesh object, "<bake> preview", parented to the bake's Volume object, whose *Volume to Mesh*
modifier (``VOLUME_TO_MESH``, Blender 3.4 – 5.x) meshes the bake's ``density`` grid at the lines'
iso level. The modifier reads the volume as the depsgraph evaluates it, so a loop or a sequence's
preview follows the scene frame. The mesh gets one solid colour (the middle of the bake's
colormap; Volume to Mesh carries no grid values onto the mesh) and is hidden from final renders
unless *Render* is turned on (then EEVEE renders it as a fast stand-in for the volume in Cycles).

``obj.licvdb_preview.show`` turns it on and off (on by default after an import in the UI, see
ops_import.import_bake); off removes the preview object, its mesh and its material. A preview
whose volume was deleted is removed at the next depsgraph update (``_remove_orphans``).
"""

import json
import subprocess

import bpy

from . import engine, material, prefs, props
from . import manifest as mf
from . import grids as G

#: Name of the Volume to Mesh modifier that marks a preview object.
MODIFIER = "licvdb preview"
#: Custom property on the preview object: the name of the bake it previews (informational).
MARK = "licvdb_preview_of"
#: Iso level as a fraction of the density's maximum: half the maximum is a spot line's
#: full-width-at-half-maximum edge; a dense (noise) bake's contrast stretch puts its mean at 0.5,
#: so only its bright streaks (the top ~10 %) are meshed.
FRACTION_SPOTS = 0.5
FRACTION_NOISE = 0.75
#: Name of the preview material's colour node.
COLOR_NODE = "preview colour"
#: Volume to Mesh adaptivity (0 = every voxel's triangles; 0.2 merges flat parts, ~10 % fewer).
ADAPTIVITY = 0.0


def preview_of(obj):
    """The preview object of the bake ``obj`` (a child with our modifier reading ``obj``), or None."""
    if obj is None:
        return None
    for child in obj.children:
        mod = child.modifiers.get(MODIFIER)
        if mod is not None and mod.type == "VOLUME_TO_MESH" and mod.object == obj:
            return child
    return None


def _recipe(obj) -> dict:
    path = obj.licvdb.manifest
    if not path:
        return {}
    try:
        return mf.read_manifest(path).recipe or {}
    except (mf.ManifestError, OSError):
        return {}


def density_max(obj, recipe) -> float:
    """The largest density of the bake: 1 under licvdb's default contrast stretch (mean ± 2.5σ →
    [0, 1]); with ``contrast: none``, what ``licvdb info --json`` reports for the first file."""
    if ((recipe.get("output") or {}).get("contrast") or "stretch") != "none":
        return 1.0
    exe = prefs.find_executable(bpy.context)
    path = bpy.path.abspath(obj.data.filepath)
    if exe is None:
        return 1.0
    try:
        proc = subprocess.run([exe, "info", "--json", path], capture_output=True, text=True, timeout=60,
                              stdin=subprocess.DEVNULL, env=engine.engine_env())
        grids = json.loads(proc.stdout).get("grids", [])
        vmax = next(g["value_range"][1] for g in grids if g.get("name") == G.DENSITY)
    except (OSError, subprocess.TimeoutExpired, ValueError, StopIteration, KeyError, IndexError, TypeError):
        return 1.0
    return float(vmax) if vmax and vmax > 0 else 1.0


def iso_level(obj) -> float:
    """The density the preview surface is drawn at: a fraction of the density's maximum (half for
    line bakes, FRACTION_NOISE for dense noise bakes)."""
    recipe = _recipe(obj)
    dense = (recipe.get("input") or {}).get("type") == "noise"
    return (FRACTION_NOISE if dense else FRACTION_SPOTS) * density_max(obj, recipe)


def preview_color(obj) -> tuple:
    """Scene-linear RGBA for the preview: the colormap's middle where the look colours by it (or by
    the baked colour grid, which the colormap made), else white."""
    look = props.look_of(obj)
    src = material.resolve_color_source(look, props.grid_names(obj))
    if src == "WHITE" or not look.colormap:
        return (0.8, 0.8, 0.8, 1.0)
    pts = sorted(look.colormap)
    lo = max((p for p in pts if p[0] <= 0.5), default=pts[0])
    hi = min((p for p in pts if p[0] >= 0.5), default=pts[-1])
    t = 0.0 if hi[0] == lo[0] else (0.5 - lo[0]) / (hi[0] - lo[0])
    rgb = [material.srgb_to_linear(a + t * (b - a)) for a, b in zip(lo[1:4], hi[1:4])]
    return (*rgb, 1.0)


def build_preview_material(mat, color) -> None:
    """A diffuse + emission surface in ``color`` (lines glow on black as in the volume look, and
    keep their shape under Material Preview's lighting); ``diffuse_color`` for Solid shading."""
    from . import compat

    tree = compat.ensure_node_tree(mat)
    nodes, links = tree.nodes, tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (400, 0)
    rgb = nodes.new("ShaderNodeRGB")
    rgb.name = rgb.label = COLOR_NODE
    rgb.location = (-250, 0)
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.location = (0, 100)
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 0.6
    emit.location = (0, -100)
    add = nodes.new("ShaderNodeAddShader")
    add.location = (200, 0)
    links.new(rgb.outputs["Color"], diffuse.inputs["Color"])
    links.new(rgb.outputs["Color"], emit.inputs["Color"])
    links.new(diffuse.outputs["BSDF"], add.inputs[0])
    links.new(emit.outputs["Emission"], add.inputs[1])
    links.new(add.outputs["Shader"], out.inputs["Surface"])
    set_material_color(mat, color)


def set_material_color(mat, color) -> None:
    """The preview's colour: the material's colour node (Material Preview, EEVEE) and its viewport
    display colour (Solid shading)."""
    tree = mat.node_tree
    node = tree.nodes.get(COLOR_NODE) if tree else None
    if node is not None:
        node.outputs["Color"].default_value = color
    mat.diffuse_color = color


def create_preview(context, obj):
    """Make (or return the existing) preview object of the bake ``obj``."""
    pv = preview_of(obj)
    if pv is not None:
        return pv
    name = f"{obj.name} preview"
    mesh = bpy.data.meshes.new(name)
    pv = bpy.data.objects.new(name, mesh)
    pv[MARK] = obj.name
    for coll in obj.users_collection:
        coll.objects.link(pv)
    if not pv.users_collection:
        context.scene.collection.objects.link(pv)
    pv.parent = obj  # identity local transform: drawn in the volume's own space, follows it
    mod = pv.modifiers.new(MODIFIER, "VOLUME_TO_MESH")
    mod.object = obj
    mod.grid_name = G.DENSITY
    mod.resolution_mode = "GRID"  # the bake's own voxels: the surface lies on the lines
    mod.threshold = iso_level(obj)
    mod.adaptivity = ADAPTIVITY
    mod.use_smooth_shade = True
    mat = bpy.data.materials.new(name)
    color = preview_color(obj)
    build_preview_material(mat, color)
    mesh.materials.append(mat)
    obj.licvdb_preview.color = color  # (its update sets the material's colour again: the same)
    pv.hide_render = True  # Cycles renders the volume; turn Render on for EEVEE
    pv.hide_select = True  # clicks in the viewport select the bake, not its preview
    return pv


def remove_preview(obj) -> bool:
    """Delete the preview of ``obj`` (object, mesh, and its material when unused); returns whether
    there was one."""
    pv = preview_of(obj)
    if pv is None:
        return False
    _delete(pv)
    return True


def _delete(pv) -> None:
    mesh = pv.data
    mats = [m for m in mesh.materials if m is not None]
    bpy.data.objects.remove(pv)
    if mesh.users == 0:
        bpy.data.meshes.remove(mesh)
    for m in mats:
        if m.users == 0:
            bpy.data.materials.remove(m)


def set_preview(context, obj, on: bool):
    """Turn the preview of the bake ``obj`` on (created) or off (removed); returns it or None."""
    if obj.licvdb_preview.show != on:
        obj.licvdb_preview.show = on  # the update callback does the work
    elif on:
        create_preview(context, obj)
    return preview_of(obj)


def _update_show(self, context):
    obj = self.id_data
    if not (isinstance(obj, bpy.types.Object) and obj.type == "VOLUME" and obj.licvdb.is_bake):
        return
    if self.show:
        create_preview(context, obj)
    else:
        remove_preview(obj)


def _update_color(self, context):
    pv = preview_of(self.id_data)
    mats = pv.data.materials if pv is not None else []
    if len(mats) and mats[0] is not None:
        set_material_color(mats[0], tuple(self.color))


def _orphans():
    """Preview objects whose volume is gone (deleted: Blender clears the modifier's object)."""
    for o in bpy.data.objects:
        if MARK in o.keys():
            mod = o.modifiers.get(MODIFIER)
            if mod is None or mod.object is None:
                yield o


@bpy.app.handlers.persistent
def _remove_orphans(scene, depsgraph=None):
    """Delete previews left behind by a deleted bake (depsgraph_update_post)."""
    if depsgraph is not None and not depsgraph.id_type_updated("OBJECT"):
        return
    for pv in list(_orphans()):
        _delete(pv)


class LICVDB_PreviewSettings(bpy.types.PropertyGroup):
    """``obj.licvdb_preview`` of a bake's Volume object."""

    show: bpy.props.BoolProperty(
        name="Surface preview", default=False, update=_update_show,
        description="Show the lines in Solid and Material Preview as a surface at their iso level (a mesh "
                    "\"<bake> preview\" made by Volume to Mesh, parented to the bake)")
    color: bpy.props.FloatVectorProperty(
        name="Colour", subtype="COLOR", size=4, min=0.0, max=1.0, default=(0.8, 0.8, 0.8, 1.0),
        update=_update_color, description="The preview's colour (set from the middle of the bake's colormap)")

    @classmethod
    def register(cls):
        bpy.types.Object.licvdb_preview = bpy.props.PointerProperty(type=cls)
        if _remove_orphans not in bpy.app.handlers.depsgraph_update_post:
            bpy.app.handlers.depsgraph_update_post.append(_remove_orphans)

    @classmethod
    def unregister(cls):
        if _remove_orphans in bpy.app.handlers.depsgraph_update_post:
            bpy.app.handlers.depsgraph_update_post.remove(_remove_orphans)
        del bpy.types.Object.licvdb_preview


def triangle_count(context, obj) -> int:
    """Triangles of the evaluated preview of ``obj`` at the current frame (0 without one)."""
    pv = preview_of(obj)
    if pv is None:
        return 0
    ev = pv.evaluated_get(context.evaluated_depsgraph_get())
    return sum(len(p.vertices) - 2 for p in ev.data.polygons)


class LICVDB_PT_preview(bpy.types.Panel):
    """Sub-panel of *LIC look*: the surface preview."""

    bl_label = "Viewport preview"
    bl_idname = "LICVDB_PT_preview"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "licvdb"
    bl_parent_id = "LICVDB_PT_look"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "VOLUME" and obj.licvdb.is_bake

    def draw_header(self, context):
        self.layout.prop(context.active_object.licvdb_preview, "show", text="")

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        pv = preview_of(obj)
        if pv is None:
            layout.label(text="Lines as a surface in Solid / Material Preview")
            return
        mod = pv.modifiers[MODIFIER]
        col = layout.column(align=True)
        col.prop(mod, "threshold", text="Iso level")
        col.prop(mod, "resolution_mode", text="Resolution")
        if mod.resolution_mode == "VOXEL_SIZE":
            col.prop(mod, "voxel_size")
        elif mod.resolution_mode == "VOXEL_AMOUNT":
            col.prop(mod, "voxel_amount")
        col.prop(mod, "adaptivity")
        layout.prop(pv, "hide_render", text="Render (EEVEE stand-in)", invert_checkbox=True)
        layout.prop(obj.licvdb_preview, "color")


classes = (LICVDB_PreviewSettings, LICVDB_PT_preview)

"""The N-panel (3D view sidebar, tab "licvdb"): the look of the active bake (and its Re-bake), and
baking from a fluid domain, a flow file or a Volume object with the same settings; the last also
in Properties > Object Data of a volume."""

import bpy

from . import compat, ops_bake, ops_bake_volume, prefs, presets
from . import grids as G


class LICVDB_PT_look(bpy.types.Panel):
    bl_label = "LIC look"
    bl_idname = "LICVDB_PT_look"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "licvdb"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "VOLUME" and obj.licvdb.is_bake

    def draw(self, context):
        layout = self.layout
        s = context.active_object.licvdb
        layout.prop(s, "look", expand=True)
        col = layout.column(align=True)
        col.prop(s, "brightness")
        col.prop(s, "line_absorption")
        row = col.row()
        row.enabled = s.look == "HALOS"
        row.prop(s, "halo_strength")
        if s.look == "HALOS" and G.HALO not in s.grid_names.split(","):
            layout.label(text="This bake has no halo grid", icon="INFO")
        layout.prop(s, "color_source")
        mat = context.active_object.active_material
        tree = mat.node_tree if mat else None  # (use_nodes is deprecated in 5.0: read the tree)
        ramp = tree.nodes.get("colormap") if tree else None
        if ramp is not None:
            layout.label(text=f"Colour ramp ({s.colormap_name or 'bake colormap'})")
            layout.template_color_ramp(ramp, "color_ramp", expand=True)
        box = layout.box()
        box.label(text=f"Grids: {s.grid_names.replace(',', ', ')}")
        if s.frames > 1:
            box.label(text=f"{s.frames} frames" + (", seamless loop" if s.cyclic else ""))
        box.label(text=f"Voxel: {s.voxel_size:.4g}")
        if s.source_kind != "NONE":
            src = s.source_path if s.source_kind == "FILE" else (s.source_object.name if s.source_object else "(gone)")
            box.label(text=f"Baked from: {src}")
            layout.operator("licvdb.rebake", icon="FILE_REFRESH")
        if compat.volume_step_rate_ignored(context.scene):
            col = layout.column(align=True)
            col.label(text="Cycles ignores the volume step rate:", icon="ERROR")
            col.label(text="turn on Render > Volumes > Biased")


class LICVDB_PT_bake(bpy.types.Panel):
    bl_label = "Bake LIC from fluid"
    bl_idname = "LICVDB_PT_bake"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "licvdb"

    def draw(self, context):
        layout = self.layout
        s = context.scene.licvdb_bake
        if prefs.find_executable(context) is None:
            col = layout.column(align=True)
            col.label(text="licvdb executable not found", icon="ERROR")
            col.label(text="Set it in Preferences > Add-ons > licvdb")
        if ops_bake.fluid_domain(context.active_object) is None:
            layout.label(text="Select a smoke domain (OpenVDB cache)", icon="INFO")
        presets.draw_preset_row(layout)
        col = layout.column(align=True)
        col.prop(s, "length")
        col.prop(s, "upsample")
        col.prop(s, "kernel")
        if s.kernel == "exp":
            col.prop(s, "decay")
        col.prop(s, "seed")
        draw_input(layout.column(align=True), s)
        col = layout.column(align=True)
        col.prop(s, "color_scalar")
        sub = col.row()
        sub.enabled = s.color_scalar != "NONE"
        sub.prop(s, "colormap")
        draw_region(layout.column(align=True), s)
        layout.prop(s, "use_frame_range")
        if s.use_frame_range:
            layout.prop(s, "range_from_cache")
            row = layout.row(align=True)
            row.enabled = not s.range_from_cache
            row.prop(s, "frame_start")
            row.prop(s, "frame_end")
        else:
            layout.prop(s, "loop_frames")
        draw_new_look(layout.column(align=True), s)
        layout.prop(s, "output_dir")
        layout.prop(s, "threads")
        layout.operator("licvdb.bake_fluid", icon="RENDER_STILL")
        layout.operator("licvdb.bake_file", text="Bake LIC from flow file…", icon="FILEBROWSER")
        if _is_source_volume(context):
            layout.operator("licvdb.bake_volume", icon="VOLUME_DATA")


def draw_input(col, s):
    """The bake settings' input: seed object, noise or spots, spot spacing, radius and halo."""
    col.prop(s, "seed_object")
    if s.seed_object is not None:
        col.row().prop(s, "seed_mode", expand=True)
        col.prop(s, "seed_spacing")
    row = col.row()
    row.enabled = s.seed_object is None  # a seed object always bakes spots
    row.prop(s, "input_type", expand=True)
    if s.input_type == "spots" or s.seed_object is not None:
        sub = col.row()
        sub.enabled = s.seed_object is None
        sub.prop(s, "spot_spacing")
        col.prop(s, "spot_radius")
        col.prop(s, "halo_scale")


def draw_region(col, s):
    """The bake settings' region of interest."""
    col.prop(s, "roi_scalar")
    if s.roi_scalar == "NONE":
        return
    col.row(align=True).prop(s, "roi_range")
    if s.roi_scalar == "speed":
        col.prop(s, "roi_relative")
    col.row().prop(s, "roi_mode", expand=True)


def draw_new_look(col, s):
    """The look new bakes get (a re-bake keeps its object's)."""
    col.prop(s, "look_set", text="Set the look of new bakes")
    if not s.look_set:
        return
    col.row().prop(s, "look", expand=True)
    col.prop(s, "look_brightness")
    col.prop(s, "look_absorption")
    row = col.row()
    row.enabled = s.look == "HALOS"
    row.prop(s, "look_halo_strength")


def draw_bake_volume(layout, context):
    """The bake-from-volume controls for the active Volume object (both panels below)."""
    obj = context.active_object
    vol = obj.data
    grids = vol.grids if vol.grids.is_loaded else None
    if grids is not None and len(grids):
        layout.prop_search(obj.licvdb, "velocity_grid", vol, "grids", text="Velocity grid")
    else:
        layout.prop(obj.licvdb, "velocity_grid")
    if not obj.licvdb.velocity_grid:
        layout.label(text="Automatic: velocity, vel, v or vel.x/y/z", icon="INFO")
    if vol.is_sequence:
        layout.label(text=f"Sequence: {vol.frame_duration} frames, one unsteady bake")
    if vol.packed_file is not None:
        layout.label(text="Packed file: unpack it to bake", icon="ERROR")
    if prefs.find_executable(context) is None:
        layout.label(text="licvdb executable not found", icon="ERROR")
    layout.label(text="Settings: Sidebar > licvdb > Bake LIC from fluid")
    layout.operator("licvdb.bake_volume", icon="RENDER_STILL")


def _is_source_volume(context) -> bool:
    return ops_bake_volume.is_source_volume(context.active_object)


class _BakeVolumePanel:
    """Shown for a Volume object that can be baked from (a mix-in before bpy.types.Panel)."""

    @classmethod
    def poll(cls, context):
        return _is_source_volume(context)

    def draw(self, context):
        draw_bake_volume(self.layout, context)


class LICVDB_PT_bake_volume(_BakeVolumePanel, bpy.types.Panel):
    """3D view sidebar: bake LIC from the active Volume object."""

    bl_label = "Bake LIC from volume"
    bl_idname = "LICVDB_PT_bake_volume"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "licvdb"


class LICVDB_PT_volume_data(_BakeVolumePanel, bpy.types.Panel):
    """Properties > Object Data of a volume: bake LIC from it."""

    bl_label = "licvdb: Bake LIC"
    bl_idname = "LICVDB_PT_volume_data"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"


classes = (LICVDB_PT_look, LICVDB_PT_bake, LICVDB_PT_bake_volume, LICVDB_PT_volume_data)

"""licvdb: import LIC bakes (.vdb) with their look, play loops, bake LIC from smoke simulations,
flow field files and Volume objects, and re-bake a result in place.

Blender 3.4+ as a legacy add-on (``bl_info``), 4.2+ as an extension (``blender_manifest.toml``).
This file only registers; the work is in the modules beside it.
"""

bl_info = {
    "name": "licvdb",
    "author": "licvdb authors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "File > Import > licvdb bake (.vdb), Bake LIC from flow file; View3D > Sidebar > licvdb; "
                "Properties > Object Data (volume)",
    "description": "Import 3D line integral convolution bakes, build their look, bake LIC from smoke and flow files",
    "category": "Import-Export",
}

import bpy

from . import (engine, manifest, material, ops_bake, ops_bake_file, ops_bake_volume, ops_import,  # noqa: F401
               ops_rebake, panel, prefs, presets, preview, props)  # (public modules)

_classes = (*prefs.classes, *props.classes, *ops_import.classes, *ops_bake.classes, *ops_bake_file.classes,
            *ops_bake_volume.classes, *ops_rebake.classes, *presets.classes, *panel.classes, *preview.classes)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)
    props.register_properties()
    bpy.types.TOPBAR_MT_file_import.append(ops_import.menu_import)
    bpy.types.TOPBAR_MT_file_import.append(ops_bake_file.menu_bake_file)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(ops_bake_file.menu_bake_file)
    bpy.types.TOPBAR_MT_file_import.remove(ops_import.menu_import)
    props.unregister_properties()
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)

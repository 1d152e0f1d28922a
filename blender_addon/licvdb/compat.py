"""Every place where the add-on behaves differently by Blender version, in one module.

The add-on runs in Blender 3.4 – 5.0. Each difference is one named predicate below, read at the
moment it is needed (never cached at import), so a test can force either branch by replacing the
predicate (``monkeypatch.setattr(compat, "node_use_nodes_deprecated", lambda: True)``).
What each guard is for, and where the facts come from, is in docs/blender.md, "Blender versions".

- ``node_use_nodes_deprecated()``: Blender 5.0 deprecated ``Material.use_nodes`` and
  ``World.use_nodes`` (always True, setting it warns and does nothing; removal planned for 6.0).
  Before 5.0 a material or world renders its node tree only with ``use_nodes`` on.
- ``has_file_handler()``: Blender 4.1+ has ``bpy.types.FileHandler`` (drag and drop of files into
  an editor calls an import operator). Read once, when ops_import defines its classes.
- ``has_volume_biased(scene)``: Cycles 5.0 renders volumes with null scattering by default and
  uses ``volume_step_rate`` / ``volume_max_steps`` only with ``scene.cycles.volume_biased`` on (ray
  marching, the only algorithm before 5.0). The property's presence is the test, not a version.
- ``cycles_draws_voxels_half_off()``: Cycles before 5.0 built without NanoVDB (distribution
  builds such as Debian's 3.4.1 and 4.3.2) renders a grid as a dense texture and draws OpenVDB
  voxel i over [i, i + 1] instead of centred on i; with NanoVDB (official builds) it samples voxel
  centres. Cycles 5.x loads grids only through NanoVDB (a build without it renders no volume),
  so there it is never half a voxel off. Measured by renders in 3.4.1 and 4.3.2
  (tests/blender/test_render.py); docs/blender.md, "Placement".
- ``has_volume_velocity(volume)``: a Volume's velocity grid for Cycles motion blur (3.1+).
- ``has_extension_user_folder()``: Blender 4.2+ gives each extension a writable user folder
  (``bpy.utils.extension_path_user``); engine.py copies a read-only bundled engine there.
"""

import bpy

#: First Blender version in which ``Material.use_nodes`` / ``World.use_nodes`` are deprecated.
USE_NODES_DEPRECATED_IN = (5, 0, 0)

#: First Blender version whose Cycles reads volume grids only through NanoVDB (no dense textures).
CYCLES_NANOVDB_ONLY_IN = (5, 0, 0)


def node_use_nodes_deprecated() -> bool:
    """True where ``use_nodes`` on materials and worlds is deprecated (Blender 5.0+)."""
    return bpy.app.version >= USE_NODES_DEPRECATED_IN


def ensure_node_tree(idblock):
    """The node tree of a material or world, turning nodes on only where needed.

    5.0+: nodes are always on; ``use_nodes`` is written only if the data-block has no node tree
    yet (5.0 creates one with every new material and world, so in practice never), and never read.
    Before 5.0: ``use_nodes`` is set when it is off or the tree is missing (setting it creates the
    default tree). Returns ``idblock.node_tree``.
    """
    if node_use_nodes_deprecated():
        if idblock.node_tree is None:
            idblock.use_nodes = True
    elif idblock.node_tree is None or not idblock.use_nodes:
        idblock.use_nodes = True
    return idblock.node_tree


def has_file_handler() -> bool:
    """True where Blender has file handlers (``bpy.types.FileHandler``, 4.1+)."""
    return hasattr(bpy.types, "FileHandler")


def has_volume_biased(scene) -> bool:
    """True where Cycles has the *Biased* volume option (``scene.cycles.volume_biased``, 5.0+)."""
    cycles = getattr(scene, "cycles", None)
    return cycles is not None and hasattr(cycles, "volume_biased")


def volume_step_rate_ignored(scene) -> bool:
    """True where Cycles would ignore ``volume_step_rate``: it has the Biased option and it is off."""
    return has_volume_biased(scene) and not scene.cycles.volume_biased


def is_distribution_build() -> bool:
    """True for a Blender built by a distribution (no build hash: Debian's), whose Cycles is taken
    to lack NanoVDB; official builds report their git hash and have NanoVDB."""
    return bpy.app.build_hash in (b"Unknown", b"unknown", b"")


def cycles_draws_voxels_half_off() -> bool:
    """True where Cycles draws OpenVDB voxel i over [i, i + 1] (its dense-texture path: before 5.0,
    without NanoVDB, taken to be a distribution build), so imports shift by −½ voxel."""
    return bpy.app.version < CYCLES_NANOVDB_ONLY_IN and is_distribution_build()


def has_volume_velocity(volume) -> bool:
    """True where a Volume names its velocity grid for motion blur (``velocity_grid``,
    ``velocity_unit``, ``velocity_scale``: Blender 3.1+)."""
    return all(hasattr(volume, a) for a in ("velocity_grid", "velocity_unit", "velocity_scale"))


def has_extension_user_folder() -> bool:
    """True where extensions have a user folder (``bpy.utils.extension_path_user``, 4.2+)."""
    return hasattr(bpy.utils, "extension_path_user")

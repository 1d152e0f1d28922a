"""Where a volume's voxels end up, per Blender version (measured; docs/blender.md, "Placement").

Two facts differ between versions:

- what ``Object.bound_box`` of a volume spans: the *centres* of the outermost active voxels in
  Blender 3.4.1 and 4.3.2, their outer *faces* (half a voxel further out on every side) in 5.2.2;
- where Cycles draws voxel i: over [i, i + 1] (index units) in its dense-texture path (builds
  without NanoVDB before 5.0: Debian's 3.4.1 and 4.3.2, measured by test_render's crossing-lines
  render), centred on i with NanoVDB (official builds; Cycles 5.x has no other path).

The add-on shifts imports by −½ voxel where Cycles draws voxels half off
(compat.cycles_draws_voxels_half_off); the tests check the drawn voxels then cover the bake's
``world_bbox`` (and the field's box) exactly.
"""

import bpy

#: First version (of those measured) whose volume bound box spans the voxels' outer faces.
BOUND_BOX_SPANS_FACES_FROM = (5, 0, 0)


def bound_box_spans_faces() -> bool:
    return bpy.app.version >= BOUND_BOX_SPANS_FACES_FROM


def cycles_draws_half_off() -> bool:
    """Whether Cycles here draws voxel i over [i, i + 1]: distribution builds (no NanoVDB) before
    5.0 (3.4.1 and 4.3.2, measured by renders). The add-on should shift imports exactly here."""
    return bpy.app.version < (5, 0, 0) and bpy.app.build_hash in (b"Unknown", b"unknown", b"")


def expected_half_voxel_shift() -> bool:
    """The shift the add-on's Auto preference should choose in this Blender."""
    return cycles_draws_half_off()


def centres_box(lo, hi, voxel):
    """World box of the outermost voxel centres, from a volume object's world bound box."""
    d = 0.5 * voxel if bound_box_spans_faces() else 0.0
    return [v + d for v in lo], [v - d for v in hi]


def drawn_box(lo, hi, voxel):
    """World box of the voxels Cycles draws, from a volume object's world bound box (which includes
    the object's translation, i.e. the add-on's shift if any): the outermost centres ± ½ voxel,
    moved by +½ voxel where Cycles draws voxel i over [i, i + 1]."""
    clo, chi = centres_box(lo, hi, voxel)
    half = 0.5 * voxel
    off = half if cycles_draws_half_off() else 0.0
    return [v - half + off for v in clo], [v + half + off for v in chi]

"""The viewport's surface preview (preview.py): a Volume to Mesh child of a bake that lies on the
bake's lines, follows the volume's frames, toggles on and off, and goes when the bake goes."""

import json
import math

import bpy
import pytest
from mathutils import Vector

from conftest import run_licvdb
from controls import vdb_module
from licvdb import ops_import, preview

#: The known line: one spot seeded here in uniform +x flow (licvdb's `uniform` field on [-1, 1]³).
SEED = (0.0, 0.2, -0.1)
RADIUS = 1.5  # output voxels
LENGTH = 8.0  # kernel half-length, output voxels


@pytest.fixture(scope="module")
def one_line(tmp_path_factory):
    """A bake of one spot in uniform flow: a single straight line along x through SEED."""
    d = tmp_path_factory.mktemp("preview")
    field = d / "uniform.vdb"
    run_licvdb("field", "uniform", "--res", "32,32,32", "--out", field, "--quiet")
    seeds = d / "seeds.txt"
    seeds.write_text(" ".join(map(str, SEED)) + "\n")
    recipe = {"field": {"path": str(field)}, "output": {"path": str(d / "line.vdb"), "upsample": 1},
              "input": {"type": "spots", "seeds": str(seeds), "radii": [RADIUS], "halo_scale": 2.0},
              "lic": {"kernel": "box", "length": LENGTH}}
    (d / "line.json").write_text(json.dumps(recipe))
    run_licvdb("bake", "--recipe", d / "line.json", "--quiet")
    return d / "line.vdb"


@pytest.fixture(scope="module")
def spots(tmp_path_factory):
    """A spot bake with halos of a 24³ ABC field: many curved lines."""
    d = tmp_path_factory.mktemp("preview_spots")
    field = d / "abc.vdb"
    run_licvdb("field", "abc", "--res", "24,24,24", "--out", field, "--quiet")
    out = d / "spots.vdb"
    run_licvdb("bake", "--field", field, "--out", out, "--input", "spots", "--spacing", "5", "--length", "8",
               "--color", "speed", "--colormap", "viridis", "--quiet")
    return out


def evaluated_vertices(pv):
    """World positions of the evaluated preview's vertices (licvdb's world coordinates, where the
    bake's lines are: the import's placement puts the volume's grids there for Cycles)."""
    ev = pv.evaluated_get(bpy.context.evaluated_depsgraph_get())
    m = pv.matrix_world
    return [m @ v.co for v in ev.data.vertices]


def test_preview_lies_on_a_known_line(one_line):
    obj = ops_import.import_bake(bpy.context, str(one_line), surface_preview=True)
    pv = preview.preview_of(obj)
    assert pv is not None and pv.type == "MESH" and pv.name == f"{obj.name} preview"
    assert pv.parent == obj
    bpy.context.view_layer.update()
    assert all(abs(a - b) < 1e-9 for ra, rb in zip(pv.matrix_world, obj.matrix_world) for a, b in zip(ra, rb))
    assert pv.hide_render and not pv.hide_viewport  # Cycles renders the volume, not the preview
    verts = evaluated_vertices(pv)
    assert len(verts) > 50
    voxel = obj.licvdb.voxel_size
    # Every vertex within the line's radius (+ a voxel of meshing) of its axis (y, z) = SEED.
    off = max(math.hypot(v.y - SEED[1], v.z - SEED[2]) for v in verts) / voxel
    assert off <= RADIUS + 1.0, off
    # ... and the surface runs along the line: about the kernel's 2 × LENGTH voxels in x.
    xs = [v.x for v in verts]
    span = (max(xs) - min(xs)) / voxel
    assert 1.0 * LENGTH <= span <= 2.0 * LENGTH + 2 * RADIUS + 2, span
    assert min(xs) - voxel <= SEED[0] <= max(xs) + voxel


def cell_corners(acc, ijk):
    """Density at the 8 voxels around the fractional index ``ijk``."""
    i0, j0, k0 = (math.floor(c) for c in ijk)
    return [acc.getValue((i0 + a, j0 + b, k0 + c)) for a in (0, 1) for b in (0, 1) for c in (0, 1)]


def test_preview_vertices_are_on_the_density_iso_surface(spots):
    obj = ops_import.import_bake(bpy.context, str(spots), surface_preview=True)
    pv = preview.preview_of(obj)
    level = pv.modifiers[preview.MODIFIER].threshold
    assert level == pytest.approx(0.5)  # half the (contrast-stretched) maximum of a spot bake
    verts = evaluated_vertices(pv)
    assert len(verts) > 100
    grid = vdb_module().read(str(spots), "density")
    acc = grid.getConstAccessor()
    # World positions against the grid's world coordinates (Blender 3.4's Volume to Mesh puts
    # voxel i's centre at i + ½ in the object's space; the import's −½ voxel shift undoes it).
    for v in verts[::7]:
        ijk = grid.transform.worldToIndex(tuple(v))
        vals = cell_corners(acc, ijk)
        assert min(vals) <= level + 1e-3 and max(vals) >= level - 1e-3, (tuple(v), ijk, vals)
    # The triangle count the panel and the docs report.
    assert preview.triangle_count(bpy.context, obj) > len(verts) // 2


def test_toggle_off_on_and_delete(spots):
    obj = ops_import.import_bake(bpy.context, str(spots), surface_preview=False)
    assert preview.preview_of(obj) is None and not obj.licvdb_preview.show
    meshes, mats = len(bpy.data.meshes), len(bpy.data.materials)
    obj.licvdb_preview.show = True
    pv = preview.preview_of(obj)
    assert pv is not None and len(evaluated_vertices(pv)) > 0
    assert bpy.context.active_object == obj  # the bake stays active
    obj.licvdb_preview.show = False
    assert preview.preview_of(obj) is None
    assert (len(bpy.data.meshes), len(bpy.data.materials)) == (meshes, mats)
    assert not [o for o in bpy.data.objects if o.name.endswith(" preview")]
    obj.licvdb_preview.show = True
    assert len(evaluated_vertices(preview.preview_of(obj))) > 0
    # Deleting the bake deletes its preview at the next depsgraph update (no orphan mesh left).
    bpy.data.objects.remove(obj)
    bpy.context.view_layer.update()
    assert not [o for o in bpy.data.objects if preview.MARK in o.keys()]
    assert len(bpy.data.meshes) == meshes
    assert not [m for m in bpy.data.materials if m.name.endswith(" preview")]


def test_preview_follows_the_loop_frames(bakes):
    obj = ops_import.import_bake(bpy.context, str(bakes["dir"] / "loop_0001.vdb"), surface_preview=True)
    assert obj.data.is_sequence and obj.data.frame_duration == 4
    pv = preview.preview_of(obj)
    assert pv.modifiers[preview.MODIFIER].threshold == pytest.approx(preview.FRACTION_NOISE)  # a noise bake
    scene = bpy.context.scene
    shapes = {}
    for frame in (1, 2, 5):
        scene.frame_set(frame)
        verts = evaluated_vertices(pv)
        assert verts
        shapes[frame] = (len(verts), round(sum(v.x + 2 * v.y + 3 * v.z for v in verts), 4))
    assert shapes[2] != shapes[1]  # the next frame of the loop
    assert shapes[5] == shapes[1]  # the loop repeats: frame 5 shows file 1 again


def test_colour_from_the_colormap(spots):
    obj = ops_import.import_bake(bpy.context, str(spots), surface_preview=True)
    pv = preview.preview_of(obj)
    mat = pv.data.materials[0]
    col = tuple(obj.licvdb_preview.color)
    assert col == pytest.approx(preview.preview_color(obj))
    assert col[1] > col[0] and col[1] > 0.1  # viridis' middle: teal
    assert tuple(mat.diffuse_color) == pytest.approx(col)
    obj.licvdb_preview.color = (1.0, 0.0, 0.0, 1.0)
    assert tuple(mat.node_tree.nodes[preview.COLOR_NODE].outputs["Color"].default_value) == pytest.approx(
        (1.0, 0.0, 0.0, 1.0))
    assert tuple(mat.diffuse_color) == pytest.approx((1.0, 0.0, 0.0, 1.0))
    out = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    assert out.inputs["Surface"].is_linked and not out.inputs["Volume"].is_linked


def test_import_operator_option(spots):
    # Background mode: no preview unless asked (a script or a test imports many bakes); in the UI the
    # checkbox is on by default.
    assert bpy.ops.licvdb.import_bake(filepath=str(spots)) == {"FINISHED"}
    assert preview.preview_of(bpy.context.active_object) is None
    assert bpy.ops.licvdb.import_bake(filepath=str(spots), surface_preview=True) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.type == "VOLUME" and preview.preview_of(obj) is not None and obj.licvdb_preview.show


def test_sub_panel_is_registered_under_the_look_panel():
    cls = bpy.types.Panel.bl_rna_get_subclass_py("LICVDB_PT_preview")
    assert cls is not None and cls.bl_parent_id == "LICVDB_PT_look"


def test_rebake_swap_keeps_one_preview(spots):
    """A re-bake imports the new bake (with its own preview in the UI) and swaps it into the old
    object: the old object's preview stays and reads the new files; the new one's goes."""
    from licvdb import ops_rebake

    old = ops_import.import_bake(bpy.context, str(spots), surface_preview=True)
    meshes = len(bpy.data.meshes)
    new = ops_import.import_bake(bpy.context, str(spots), surface_preview=True)
    assert len(bpy.data.meshes) == meshes + 1
    ops_rebake.swap_bake(bpy.context, old, new)
    assert len(bpy.data.meshes) == meshes
    assert [o for o in bpy.data.objects if preview.MARK in o.keys()] == [preview.preview_of(old)]
    assert len(evaluated_vertices(preview.preview_of(old))) > 0

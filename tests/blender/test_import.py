"""licvdb.import_bake: a still, a cyclic loop, the material, and placement in world space."""

import os
import shutil

import bpy
import pytest
from mathutils import Vector

import placement
from conftest import run_licvdb
from licvdb import manifest as mf
from licvdb import ops_import


def import_one(path, **kw):
    result = bpy.ops.licvdb.import_bake(filepath=str(path), **kw)
    assert result == {"FINISHED"}, result
    obj = bpy.context.active_object
    assert obj is not None and obj.type == "VOLUME"
    return obj


def volume_links(mat):
    """(from node, from socket, to socket) of every link into the material output."""
    out = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    return [(l.from_node, l.from_socket.name, l.to_socket.name) for l in mat.node_tree.links if l.to_node == out]


def upstream(node, seen=None):
    """Every node feeding ``node``."""
    seen = set() if seen is None else seen
    for inp in node.inputs:
        for link in inp.links:
            if link.from_node.name not in seen:
                seen.add(link.from_node.name)
                upstream(link.from_node, seen)
    return seen


def test_import_still(bakes):
    obj = import_one(bakes["still"])
    vol = obj.data
    assert not vol.is_sequence
    assert vol.grids.load()
    names = {g.name for g in vol.grids}
    assert {"density", "color", "scalar"} <= names
    assert obj.licvdb.is_bake and obj.licvdb.colormap_name == "viridis"
    # A dense (noise) bake gets the dense look's brightness and absorption.
    assert (obj.licvdb.brightness, obj.licvdb.line_absorption) == pytest.approx(ops_import.DENSE_LOOK)
    assert obj.licvdb.look == "LINES"  # no halo grid
    man = mf.read_manifest(mf.manifest_path(str(bakes["still"])))
    assert obj.licvdb.voxel_size == pytest.approx(man.voxel_size)

    mat = obj.active_material
    assert mat is not None
    links = volume_links(mat)
    assert [s for _, _, s in links] == ["Volume"], "only the Volume output may be connected"
    feeding = upstream(links[0][0])
    nodes = mat.node_tree.nodes
    attrs = {nodes[n].attribute_name for n in feeding if nodes[n].bl_idname == "ShaderNodeAttribute"}
    assert attrs == {"density", "scalar"}, attrs  # AUTO colour: scalar through the ramp
    ramp = nodes["colormap"].color_ramp
    assert len(ramp.elements) == 32  # viridis' 33 points thinned to Blender's maximum
    # Ends of the ramp are viridis' ends (sRGB 0.267,0.0049,0.3294 → linear).
    assert ramp.elements[0].color[0] == pytest.approx(0.0584, abs=2e-3)
    assert ramp.elements[-1].color[1] == pytest.approx(0.7998, abs=2e-3)

    # Switching the colour source to the color grid rewires the emission colour.
    obj.licvdb.color_source = "COLOR"
    nodes = obj.active_material.node_tree.nodes
    emission = nodes["line emission"]
    assert emission.inputs["Color"].links[0].from_node.attribute_name == "color"
    assert "colormap" not in nodes
    obj.licvdb.brightness = 3.0
    strength = obj.active_material.node_tree.nodes["line brightness"].inputs[1].default_value
    assert strength == pytest.approx(3.0 / obj.licvdb.voxel_size, rel=1e-5)


def test_render_settings_after_import(bakes):
    import_one(bakes["still"])
    scene = bpy.context.scene
    assert scene.render.engine == "CYCLES"
    assert scene.cycles.use_denoising is False  # Debian's Blender has no OpenImageDenoise
    bg = scene.world.node_tree.nodes["Background"]
    assert tuple(bg.inputs["Color"].default_value)[:3] == (0.0, 0.0, 0.0)


def test_import_cyclic_loop(bakes):
    loop = bakes["loop"]
    first = str(loop).replace(".vdb", "_0001.vdb")
    third = str(loop).replace(".vdb", "_0003.vdb")
    bpy.context.scene.frame_start = 5
    obj = import_one(third)  # any frame of the loop imports the whole loop
    vol = obj.data
    assert vol.is_sequence
    assert vol.frame_duration == 4
    assert vol.frame_start == 5
    assert vol.sequence_mode == "REPEAT"
    assert os.path.samefile(bpy.path.abspath(vol.filepath), first)
    assert obj.licvdb.cyclic and obj.licvdb.frames == 4

    def file_at(frame):
        bpy.context.scene.frame_set(frame)
        dg = bpy.context.evaluated_depsgraph_get()
        grids = obj.evaluated_get(dg).data.grids
        return grids.frame, os.path.basename(grids.frame_filepath)

    assert file_at(5) == (1, "loop_0001.vdb")
    assert file_at(8) == (4, "loop_0004.vdb")
    assert file_at(9) == (1, "loop_0001.vdb")  # frame N+1 of the loop shows file 1 again
    assert file_at(5 + 4 * 25 + 2) == (3, "loop_0003.vdb")  # and forever


def test_bake_writes_licvdb_json_beside_its_recipe(bakes, tmp_path):
    # `--recipe jet.json --out jet.vdb` used to be refused: the manifest was jet.json.
    recipe = tmp_path / "jet.json"
    recipe.write_text('{"lic": {"length": 6}}')
    run_licvdb("bake", "--recipe", recipe, "--field", bakes["field"], "--out", tmp_path / "jet.vdb", "--quiet")
    assert recipe.read_text() == '{"lic": {"length": 6}}'
    assert (tmp_path / "jet.licvdb.json").is_file()
    obj = import_one(tmp_path / "jet.vdb")  # the recipe jet.json beside it is not mistaken for a manifest
    assert obj.licvdb.is_bake
    assert os.path.samefile(obj.licvdb.manifest, tmp_path / "jet.licvdb.json")


def test_import_bake_with_old_manifest_name(bakes, tmp_path):
    """Bakes made before the rename have OUT.json (a still) or one OUT.json (a loop)."""
    d = bakes["dir"]
    for name in ("still.vdb", "loop_0001.vdb", "loop_0002.vdb", "loop_0003.vdb", "loop_0004.vdb"):
        shutil.copy(d / name, tmp_path / name)
    shutil.copy(mf.manifest_path(str(d / "still.vdb")), tmp_path / "still.json")
    shutil.copy(mf.manifest_path(str(d / "loop.vdb")), tmp_path / "loop.json")
    still = import_one(tmp_path / "still.vdb")
    assert still.licvdb.is_bake and still.licvdb.colormap_name == "viridis"
    assert os.path.samefile(still.licvdb.manifest, tmp_path / "still.json")
    loop = import_one(tmp_path / "loop_0002.vdb")
    assert loop.data.is_sequence and loop.data.frame_duration == 4
    assert loop.licvdb.cyclic and loop.licvdb.frames == 4
    assert os.path.samefile(loop.licvdb.manifest, tmp_path / "loop.json")


def test_import_multiselect_dedupes_loop(bakes):
    d = str(bakes["dir"])
    files = [{"name": f"loop_000{i}.vdb"} for i in (1, 2, 3, 4)] + [{"name": "still.vdb"}]
    result = bpy.ops.licvdb.import_bake(directory=d, files=files)
    assert result == {"FINISHED"}
    vols = [o for o in bpy.context.scene.objects if o.type == "VOLUME"]
    assert sorted(o.name for o in vols) == ["loop", "still"]


def test_import_errors_are_reported(tmp_path):
    missing = tmp_path / "nope.vdb"
    with pytest.raises(RuntimeError, match="does not exist"):
        bpy.ops.licvdb.import_bake(filepath=str(missing))
    bad = tmp_path / "bad.vdb"
    bad.write_bytes(b"not a vdb")
    with pytest.raises(RuntimeError, match="cannot read"):
        bpy.ops.licvdb.import_bake(filepath=str(bad))
    assert not [o for o in bpy.context.scene.objects if o.type == "VOLUME"]


def world_bounds(obj):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    corners = [ev.matrix_world @ Vector(c) for c in ev.bound_box]
    lo = [min(c[a] for c in corners) for a in range(3)]
    hi = [max(c[a] for c in corners) for a in range(3)]
    return lo, hi


def test_placement_matches_field_bbox(bakes):
    """The imported bake lines up with the field's world bounding box.

    licvdb's world_bbox spans the outermost voxels' outer faces (centres ± ½ voxel). What
    Blender's bound box of a volume spans, and where Cycles draws a voxel, depend on the version
    (placement.py, measured): the bound box spans voxel centres in 3.4.1 and 4.3.2 and outer
    faces in 5.2.2; Cycles without NanoVDB before 5.0 (Debian's 3.4.1 and 4.3.2) draws voxel i
    over [i, i + 1] instead of [i − ½, i + ½], so the add-on moves the object by −½ voxel
    there (test_render checks the rendered lines are centred). The cells Cycles renders must
    then cover the manifest's world_bbox exactly."""
    obj = import_one(bakes["still"])
    lo, hi = world_bounds(obj)
    half = 0.5 * obj.licvdb.voxel_size
    assert obj.licvdb.half_voxel_shift == placement.expected_half_voxel_shift()
    # The bound box itself, as this version defines it: centres (± ½ voxel for faces) of the
    # manifest's voxels, plus the object's shift.
    shift = -half if obj.licvdb.half_voxel_shift else 0.0
    man = mf.read_manifest(mf.manifest_path(str(bakes["still"])))
    mlo, mhi = man.grid("density").world_bbox
    clo, chi = placement.centres_box(lo, hi, obj.licvdb.voxel_size)
    for a in range(3):
        assert clo[a] == pytest.approx(mlo[a] + half + shift, abs=1e-3 * half), (a, clo, mlo)
        assert chi[a] == pytest.approx(mhi[a] - half + shift, abs=1e-3 * half), (a, chi, mhi)
    rendered_lo, rendered_hi = placement.drawn_box(lo, hi, obj.licvdb.voxel_size)
    for a in range(3):
        assert rendered_lo[a] == pytest.approx(mlo[a], abs=1e-3 * half), (a, rendered_lo, mlo)
        assert rendered_hi[a] == pytest.approx(mhi[a], abs=1e-3 * half), (a, rendered_hi, mhi)
    # The output covers the field's world box (centres ± ½ field voxel) to within half an
    # output voxel.
    field = next(g for g in bakes["field_info"]["grids"] if g["name"] == "velocity")
    flo, fhi = field["world_bbox"]
    for a in range(3):
        assert rendered_lo[a] == pytest.approx(flo[a], abs=half + 1e-6), (a, rendered_lo, flo)
        assert rendered_hi[a] == pytest.approx(fhi[a], abs=half + 1e-6), (a, rendered_hi, fhi)
    print(f"placement (Blender {bpy.app.version_string}, bound box spans "
          f"{'faces' if placement.bound_box_spans_faces() else 'centres'}): bound box {lo} .. {hi}; rendered "
          f"{rendered_lo} .. {rendered_hi}; manifest {mlo} .. {mhi}; field {flo} .. {fhi}; half voxel {half:.4f}, "
          f"shift {shift:.4f}")


def test_import_half_float_spot_bake(bakes, tmp_path):
    """A spot bake stored with --half (16-bit on disk) imports like a full-precision one: the same
    grids, read by Blender as float grids, at the same place, with the halo look."""
    paths = {}
    for name, extra in (("full", []), ("half", ["--half"])):
        out = tmp_path / f"{name}.vdb"
        run_licvdb("bake", "--field", bakes["field"], "--out", out, "--input", "spots", "--spacing", "8",
                   "--length", "8", "--write-tangent", "--quiet", *extra)
        paths[name] = out
    assert os.path.getsize(paths["half"]) < 0.8 * os.path.getsize(paths["full"])
    bounds, types = {}, {}
    for name, path in paths.items():
        obj = import_one(path)
        assert obj.data.grids.load(), f"Blender cannot load {path}"
        types[name] = {g.name: g.data_type for g in obj.data.grids}
        bounds[name] = world_bounds(obj)
        assert obj.licvdb.look == "HALOS"
    assert types["half"] == types["full"]
    assert types["half"]["density"] == "FLOAT" and types["half"]["halo"] == "FLOAT"
    assert types["half"]["tangent"] == "VECTOR_FLOAT"
    for a in range(3):
        assert bounds["half"][0][a] == pytest.approx(bounds["full"][0][a], abs=1e-9)
        assert bounds["half"][1][a] == pytest.approx(bounds["full"][1][a], abs=1e-9)

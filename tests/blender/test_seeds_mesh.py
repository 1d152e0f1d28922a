"""Seeds from a mesh (scene.licvdb_bake.seed_object): points sampled on or inside a Mesh object in
world space become licvdb's explicit spots, for every bake operator and re-bake."""

import math
import os

import bpy
import pytest
from mathutils import Vector
from mathutils.bvhtree import BVHTree

from licvdb import manifest as mf
from licvdb import ops_bake, ops_bake_file, seeds

from conftest import run_licvdb
from bake_util import make_active, small_field
from controls import vdb_module
from test_fluid import DOMAIN_LOC, smoke  # noqa: F401 (the smoke fixture)

CENTRE = (3.2, 3.1, 3.0)  # inside the 16³ ABC field's box, [0, 2π]³


@pytest.fixture
def field(tmp_path):
    return small_field(tmp_path, length=4.0)


def sphere(name="seed sphere"):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=CENTRE)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (1.5, 1.5, 1.5)
    bpy.context.view_layer.update()
    return obj


def world_bvh(obj):
    verts, tris, _ = seeds.world_triangles(bpy.context, obj)
    area = sum(0.5 * (verts[j] - verts[i]).cross(verts[k] - verts[i]).length for i, j, k in tris)
    return BVHTree.FromPolygons(verts, tris, all_triangles=True), area


def use_seeds(obj, mode="SURFACE", spacing=0.6):
    s = bpy.context.scene.licvdb_bake
    s.seed_object, s.seed_mode, s.seed_spacing = obj, mode, spacing
    s.color_scalar = "NONE"
    return s


def test_surface_seeds_lie_on_the_mesh_and_the_bake_uses_them(field):
    obj = sphere()
    obj.location.x = 5.6  # partly off the field's box (x ≤ 2π): those points are dropped
    bpy.context.view_layer.update()
    s = use_seeds(obj, "SURFACE", 0.6)
    s.spot_radius = 1.0
    bvh, area = world_bvh(obj)
    pts = seeds.sample(bpy.context, obj, "SURFACE", 0.6, s.seed)
    assert abs(len(pts) - area / 0.36) <= 0.3 * area / 0.36, (len(pts), area / 0.36)
    for p in pts:
        assert bvh.find_nearest(p)[3] < 1e-4
    assert seeds.sample(bpy.context, obj, "SURFACE", 0.6, s.seed) == pts  # deterministic

    job, finish = ops_bake_file.plan_file_bake(bpy.context, str(field))
    recipe = job.tasks[0][1]
    assert recipe["input"]["type"] == "spots" and recipe["input"]["seeds"].endswith(".seeds.txt")
    written = seeds.read_seeds(recipe["input"]["seeds"])
    assert len(written) == len(pts)
    recipe["output"]["write_input"] = True
    job.run(timeout=120)
    assert job.error is None, job.error
    summary = job.done_outputs[0][2]
    used = summary["spots"]["seeds"]
    # licvdb reads every point written and drops (and counts) those off the output domain.
    assert used["points"] == len(written) and 0 < used["dropped"] < len(written)
    new = finish(bpy.context)
    assert new.licvdb.is_bake and new.licvdb.source_kind == "FILE"
    assert mf.read_manifest(new.licvdb.manifest).recipe["input"]["seeds"] == recipe["input"]["seeds"]

    vdb = vdb_module()
    grid = vdb.read(recipe["output"]["path"], "input")
    voxel = grid.transform.voxelSize()[0]
    limit = 0.6 + s.spot_radius * voxel + voxel  # spacing + spot radius (+ a voxel of rasterisation)
    n = 0
    for item in grid.iterOnValues():
        if item["value"] <= 0.5:
            continue
        lo, hi = item["min"], item["max"]
        for i in range(lo[0], hi[0] + 1):
            for j in range(lo[1], hi[1] + 1):
                for k in range(lo[2], hi[2] + 1):
                    w = Vector(grid.transform.indexToWorld((i, j, k)))
                    assert bvh.find_nearest(w)[3] <= limit, (tuple(w), bvh.find_nearest(w)[3])
                    n += 1
    assert n > 0


def test_inside_seeds_are_a_lattice_inside_a_cube():
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.3, -0.2, 0.1), rotation=(0.3, 0.2, 0.1))
    cube = bpy.context.active_object
    bpy.context.view_layer.update()
    pitch = 0.25
    pts = seeds.sample(bpy.context, cube, "INSIDE", pitch, 1)
    assert 0.7 * 8.0 / pitch ** 3 < len(pts) < 1.3 * 8.0 / pitch ** 3
    inv = cube.matrix_world.inverted()
    for p in pts:
        q = inv @ p
        assert max(abs(c) for c in q) <= 1.0 + 1e-6, tuple(q)
        for c in p:
            assert abs(c / pitch - round(c / pitch)) < 1e-6
    assert len({tuple(round(c / pitch) for c in p) for p in pts}) == len(pts)


def test_refusals_and_no_seed_object(field, tmp_path):
    bpy.ops.mesh.primitive_plane_add(size=3.0, location=CENTRE)
    plane = bpy.context.active_object
    use_seeds(plane, "INSIDE", 0.5)
    with pytest.raises(RuntimeError, match=r"not a closed mesh"):
        bpy.ops.licvdb.bake_file(filepath=str(field))
    with pytest.raises(seeds.SeedError, match=r"not a closed mesh"):
        seeds.sample(bpy.context, plane, "INSIDE", 0.5, 1)

    # A failed bake removes the seeds it wrote.
    use_seeds(sphere(), "SURFACE", 0.6)
    with pytest.raises(RuntimeError, match=r"licvdb bake failed"):
        bpy.ops.licvdb.bake_file(filepath=str(field), grid="no_such_grid")
    assert not os.listdir(field.parent / "licvdb")

    # No seed object: the old behaviour, a noise recipe without seeds.
    s = bpy.context.scene.licvdb_bake
    s.seed_object = None
    job, _ = ops_bake_file.plan_file_bake(bpy.context, str(field))
    assert job.tasks[0][1]["input"] == {"type": "noise", "seed": s.seed}
    job.finished  # noqa: B018 (removes the job's work folder)

    # A volume sequence with a seed object: refused before licvdb runs, nothing written.
    d = tmp_path / "seq"
    d.mkdir()
    run_licvdb("field", "tornado", "--res", "16,16,16", "--frames", "1,2", "--out", d / "T_####.vdb", "--quiet")
    vol = bpy.data.volumes.new("seq")
    vol.filepath = str(d / "T_0001.vdb")
    vol.is_sequence = True
    vol.frame_duration = 2
    src = bpy.data.objects.new("seq", vol)
    bpy.context.collection.objects.link(src)
    use_seeds(sphere(), "SURFACE", 0.6)
    make_active(src)
    with pytest.raises(RuntimeError, match=r"unsteady sequence.*Seed object"):
        bpy.ops.licvdb.bake_volume()
    assert not os.path.exists(d / "licvdb") or not os.listdir(d / "licvdb")


def test_rebake_resamples_the_moved_mesh(field):
    obj = sphere()
    use_seeds(obj, "SURFACE", 0.6)
    assert bpy.ops.licvdb.bake_file(filepath=str(field)) == {"FINISHED"}
    result = bpy.context.active_object
    first = mf.read_manifest(result.licvdb.manifest).recipe["input"]["seeds"]
    a = seeds.read_seeds(first)
    obj.location.x -= 1.0
    bpy.context.view_layer.update()
    make_active(result)
    assert bpy.ops.licvdb.rebake() == {"FINISHED"}
    second = mf.read_manifest(result.licvdb.manifest).recipe["input"]["seeds"]
    assert second != first
    b = seeds.read_seeds(second)
    mean = lambda pts, k: sum(p[k] for p in pts) / len(pts)  # noqa: E731
    assert math.isclose(mean(b, 0), mean(a, 0) - 1.0, abs_tol=1e-5)  # same seed, same points, moved
    assert math.isclose(mean(b, 1), mean(a, 1), abs_tol=1e-5)
    bvh, _ = world_bvh(obj)
    assert all(bvh.find_nearest(Vector(p))[3] < 1e-4 for p in b)


def test_volume_bake_seeds_in_the_moved_sources_coordinates(field):
    """bake_volume draws the field in the source's local space: the seeds are written mapped by the
    source's inverse world matrix, so they land on the mesh once placed."""
    vol = bpy.data.volumes.new("flow")
    vol.filepath = str(field)
    src = bpy.data.objects.new("flow", vol)
    bpy.context.collection.objects.link(src)
    src.location = (1.0, -2.0, 0.5)
    src.scale = (2.0, 2.0, 2.0)
    obj = sphere()
    obj.location = src.matrix_world @ Vector(CENTRE)
    bpy.context.view_layer.update()
    use_seeds(obj, "SURFACE", 1.0)
    make_active(src)
    assert bpy.ops.licvdb.bake_volume() == {"FINISHED"}
    result = bpy.context.active_object
    pts = seeds.read_seeds(mf.read_manifest(result.licvdb.manifest).recipe["input"]["seeds"])
    bvh, _ = world_bvh(obj)
    assert pts and all(bvh.find_nearest(src.matrix_world @ Vector(p))[3] < 1e-4 for p in pts)


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_fluid_bake_seeds_in_cache_coordinates_and_frame_range_refused(smoke):
    ds = ops_bake.fluid_domain(smoke)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=DOMAIN_LOC)
    obj = bpy.context.active_object
    use_seeds(obj, "SURFACE", 0.2)
    bpy.context.scene.frame_set(3)
    make_active(smoke)
    job, _ = ops_bake.plan_bake(bpy.context, smoke)
    pts = seeds.read_seeds(job.tasks[0][1]["input"]["seeds"])
    job.finished  # noqa: B018 (removes the job's work folder)
    placement = ops_bake.domain_placement(smoke, ds, ops_bake.cache_voxel_size(ops_bake.cache_data_file(ds, 3)))
    bvh, _ = world_bvh(obj)
    assert pts and all(bvh.find_nearest(placement @ Vector(p))[3] < 1e-4 for p in pts)
    assert bpy.ops.licvdb.bake_fluid() == {"FINISHED"}

    s = bpy.context.scene.licvdb_bake
    s.use_frame_range, s.range_from_cache = True, True
    make_active(smoke)
    with pytest.raises(RuntimeError, match=r"frame range 1-4 is baked as one unsteady sequence"):
        bpy.ops.licvdb.bake_fluid()

"""licvdb.bake_fluid end to end on a tiny smoke simulation baked in the test."""

import glob
import os
import time

import bpy
import numpy as np
import pytest
from mathutils import Matrix, Vector

from conftest import licvdb_exe, run_licvdb
from bake_util import make_active, wait_until_running
import controls
from controls import vdb_module
from licvdb import ops_bake, ops_import

RES = 16
DOMAIN_LOC = (0.3, -0.2, 0.5)  # a size-2 cube: local box [-1, 1]³
SPHERE_LOC = (0.45, -0.35, -0.1)
FRAMES = 4


def make_smoke(cache_dir):
    """A gas domain (res 16, OpenVDB cache) with a smoke inflow; simulates frames 1..4 (the
    replay cache writes fluid_data_NNNN.vdb as the frames are evaluated). Returns the domain."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_cube_add(size=2, location=DOMAIN_LOC)
    dom = bpy.context.active_object
    dom.name = "Smoke Domain"
    mod = dom.modifiers.new("Fluid", "FLUID")
    mod.fluid_type = "DOMAIN"
    ds = mod.domain_settings
    ds.domain_type = "GAS"
    ds.resolution_max = RES
    ds.cache_directory = str(cache_dir)
    ds.cache_data_format = "OPENVDB"
    ds.cache_type = "REPLAY"
    ds.cache_frame_start, ds.cache_frame_end = 1, FRAMES
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=SPHERE_LOC)
    flow = bpy.context.active_object
    fm = flow.modifiers.new("Fluid", "FLUID")
    fm.fluid_type = "FLOW"
    fs = fm.flow_settings
    fs.flow_type = "SMOKE"
    fs.flow_behavior = "INFLOW"
    fs.use_initial_velocity = True
    fs.velocity_coord = (0.0, 0.0, 1.5)
    scene.frame_start, scene.frame_end = 1, FRAMES
    for f in range(1, FRAMES + 1):
        scene.frame_set(f)
    for f in range(1, FRAMES + 1):
        assert os.path.isfile(ops_bake.cache_data_file(ds, f)), f"simulation did not write frame {f}"
    return make_active(dom)


@pytest.fixture
def smoke(tmp_path):
    """The smoke domain of make_smoke, simulated. Where the smoke control shows that this Blender
    aborts on any smoke simulation (conftest.py has then made the test an expected failure), the
    simulation runs in a child Blender instead, whose abort is the test's expected failure; here
    it would end the whole run."""
    if not controls.smoke_simulation().works:
        controls.run_smoke(tmp_path / "cache")
        pytest.fail("the smoke control says this Blender aborts on any smoke simulation, but the test's "
                    "simulation ran in a child Blender: the control is wrong")
    dom = make_smoke(tmp_path / "cache")
    s = bpy.context.scene.licvdb_bake
    s.length = 6.0
    s.upsample = 2
    s.color_scalar = "speed"
    s.output_dir = str(tmp_path / "out")
    return dom


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_cache_velocity_grid_is_readable(smoke):
    """What mantaflow writes in Blender 3.4: a vec3s `velocity` grid of class staggered, stored as
    half floats, active where there is smoke; licvdb reads it."""
    vdb = vdb_module()

    path = ops_bake.cache_data_file(ops_bake.fluid_domain(smoke), 3)
    meta = {g.name: g for g in vdb.readAllGridMetadata(path)}
    assert "velocity" in meta and "density" in meta
    vel = meta["velocity"]
    assert vel.valueTypeName == "vec3s"
    assert vel.gridClass == "staggered"
    assert vel["is_saved_as_half_float"] is True
    info = run_licvdb("info", path, "--json")
    assert '"velocity"' in info


def test_placement_of_cache_coordinates(smoke):
    """domain_placement puts the cache's density where the emitter is (mantaflow writes cell i at
    i × cell, Blender's cell i covers [lower + i·cell, lower + (i+1)·cell])."""
    vdb = vdb_module()

    ds = ops_bake.fluid_domain(smoke)
    g = vdb.read(ops_bake.cache_data_file(ds, 1), "density")
    cell = 2.0 / RES
    assert g.transform.voxelSize()[0] == pytest.approx(cell)
    dense = np.zeros((RES, RES, RES), np.float32)
    g.copyToArray(dense, ijk=(0, 0, 0))
    idx = np.stack(np.meshgrid(*[np.arange(RES)] * 3, indexing="ij"), axis=-1)
    centroid = (idx * dense[..., None]).sum(axis=(0, 1, 2)) / dense.sum()
    world = ops_bake.domain_placement(smoke, ds, cell) @ Vector(centroid * cell)
    # x and y are symmetric about the sphere's centre (the inflow pushes z up).
    assert world.x == pytest.approx(SPHERE_LOC[0], abs=0.25 * cell), world
    assert world.y == pytest.approx(SPHERE_LOC[1], abs=0.25 * cell), world


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_bake_fluid_current_frame(smoke, tmp_path):
    bpy.context.scene.frame_set(3)
    t0 = time.monotonic()
    assert bpy.ops.licvdb.bake_fluid() == {"FINISHED"}
    seconds = time.monotonic() - t0
    obj = bpy.context.active_object
    assert obj.type == "VOLUME" and obj.licvdb.is_bake and obj is not smoke
    vol = obj.data
    assert not vol.is_sequence
    assert vol.grids.load()
    assert {"density", "color", "scalar"} <= {g.name for g in vol.grids}
    assert os.path.basename(vol.filepath).endswith("_f0003.vdb")
    assert os.path.dirname(bpy.path.abspath(vol.filepath)) == str(tmp_path / "out")
    # Placed on the domain: the object's matrix is the cache → world placement (plus the
    # half-voxel correction), so the LIC lies inside the domain.
    ds = ops_bake.fluid_domain(smoke)
    out_voxel = (2.0 / RES) / 2
    shift = -0.5 * out_voxel if obj.licvdb.half_voxel_shift else 0.0
    expected = ops_bake.domain_placement(smoke, ds, 2.0 / RES) @ Matrix.Translation((shift,) * 3)
    for a in range(4):
        for b in range(4):
            assert obj.matrix_world[a][b] == pytest.approx(expected[a][b], abs=1e-5)
    corners = [obj.matrix_world @ Vector(c) for c in obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).bound_box]
    for a in range(3):
        lo, hi = DOMAIN_LOC[a] - 1.0, DOMAIN_LOC[a] + 1.0
        assert all(lo - 1e-4 <= c[a] <= hi + 1e-4 for c in corners), (a, corners)
    # The look was built for the bake: colour through the ramp, only the Volume output linked.
    nodes = obj.active_material.node_tree.nodes
    assert "colormap" in nodes
    print(f"bake_fluid: one frame of a {RES}³ smoke domain baked and imported in {seconds:.2f} s")


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_rebake_fluid_in_place(smoke):
    """licvdb.rebake of a fluid bake (test_rebake.py has the file and volume kinds): the same
    object and material (its node edit kept), still placed on the domain, with the new upsample's
    half-voxel correction and new files."""
    bpy.context.scene.frame_set(2)
    assert bpy.ops.licvdb.bake_fluid() == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.licvdb.source_kind == "FLUID" and obj.licvdb.source_object is smoke
    mat = obj.active_material
    mat.node_tree.nodes["black absorption"].inputs["Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    old = bpy.path.abspath(obj.data.filepath)
    bpy.context.scene.licvdb_bake.upsample = 1
    assert bpy.ops.licvdb.rebake() == {"FINISHED"}
    assert bpy.context.active_object == obj and obj.active_material == mat
    assert mat.node_tree.nodes["black absorption"].inputs["Color"].default_value[2] == pytest.approx(0.3)
    new = bpy.path.abspath(obj.data.filepath)
    assert new != old and os.path.isfile(new) and os.path.isfile(old) and new.endswith("_f0002.vdb")
    out_voxel = 2.0 / RES
    shift = -0.5 * out_voxel if obj.licvdb.half_voxel_shift else 0.0
    assert tuple(obj.licvdb.placement_shift) == pytest.approx((shift,) * 3)
    expected = ops_bake.domain_placement(smoke, ops_bake.fluid_domain(smoke), 2.0 / RES) @ \
        Matrix.Translation((shift,) * 3)
    for a in range(4):
        for b in range(4):
            assert obj.matrix_world[a][b] == pytest.approx(expected[a][b], abs=1e-5)


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_bake_fluid_frame_range_is_a_sequence(smoke):
    s = bpy.context.scene.licvdb_bake
    s.use_frame_range = True
    s.range_from_cache = False
    s.frame_start, s.frame_end = 2, 4
    s.color_scalar = "NONE"
    assert bpy.ops.licvdb.bake_fluid() == {"FINISHED"}
    obj = bpy.context.active_object
    vol = obj.data
    assert vol.is_sequence and vol.frame_duration == 3 and vol.sequence_mode == "CLIP"
    assert vol.frame_start == 2
    bpy.context.scene.frame_set(3)
    grids = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.grids
    assert grids.frame == 3 and grids.frame_filepath.endswith("_0003.vdb")
    assert grids.is_loaded or grids.load()
    # One coherent unsteady bake (the texture carried by the smoke), not three separate stills.
    vdb = vdb_module()
    meta = {g.name: g for g in vdb.readAllGridMetadata(grids.frame_filepath)}["density"]
    assert meta["lic_unsteady"] is True and meta["lic_cyclic"] is False
    assert meta["lic_frame"] == 3 and meta["lic_first_frame"] == 2 and meta["lic_frames"] == 3
    # Imported again from any of its files, the sequence plays in step with the simulation.
    again = ops_import.import_bake(bpy.context, grids.frame_filepath)
    assert again.data.frame_start == 2 and again.data.sequence_mode == "CLIP" and again.data.frame_duration == 3


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_bake_fluid_cached_range_is_one_coherent_sequence(smoke):
    """By default a frame range is the domain's cache range (1-4 here), baked as one sequence whose
    texture is carried by the smoke: consecutive frames are alike, but not identical."""
    vdb = vdb_module()
    s = bpy.context.scene.licvdb_bake
    s.use_frame_range = True
    s.color_scalar = "NONE"
    s.length = 4.0
    assert bpy.ops.licvdb.bake_fluid() == {"FINISHED"}
    vol = bpy.context.active_object.data
    assert vol.is_sequence and vol.frame_start == 1 and vol.frame_duration == FRAMES and vol.sequence_mode == "CLIP"
    first = vol.filepath
    assert first.endswith("_0001.vdb")
    metas = [{g.name: g for g in vdb.readAllGridMetadata(first.replace("_0001.vdb", f"_{f:04d}.vdb"))}["density"]
             for f in range(1, FRAMES + 1)]
    assert [m["lic_frame"] for m in metas] == list(range(1, FRAMES + 1))
    assert all(m["lic_unsteady"] for m in metas)
    a = vdb.read(first.replace("_0001.vdb", "_0003.vdb"), "density")
    b = vdb.read(first.replace("_0001.vdb", "_0004.vdb"), "density")
    acc = b.getConstAccessor()
    pairs = [(it.value, acc.getValue(it.min)) for it in a.citerOnValues() if it.count == 1]
    x, y = np.array(pairs).T
    r = float(np.corrcoef(x, y)[0, 1])
    assert 0.3 < r < 0.999, f"frames 3 and 4 correlate {r}: carried texture should be alike, not identical"


@pytest.mark.reads_blender_vdb  # licvdb reads this Blender's smoke cache
def test_bake_fluid_one_frame_as_a_loop(smoke):
    s = bpy.context.scene.licvdb_bake
    s.loop_frames = 3
    s.color_scalar = "NONE"
    bpy.context.scene.frame_start = 10
    bpy.context.scene.frame_set(4)
    assert bpy.ops.licvdb.bake_fluid() == {"FINISHED"}
    vol = bpy.context.active_object.data
    assert vol.is_sequence and vol.frame_duration == 3 and vol.sequence_mode == "REPEAT"
    assert vol.frame_start == 10
    assert os.path.basename(vol.filepath).endswith("_f0004_0001.vdb")


def test_bake_fluid_errors_are_reported(smoke, tmp_path):
    prefs = bpy.context.preferences.addons["licvdb"].preferences
    s = bpy.context.scene.licvdb_bake
    # A frame the simulation has not cached.
    bpy.context.scene.frame_set(FRAMES + 5)
    with pytest.raises(RuntimeError, match="bake the simulation first"):
        bpy.ops.licvdb.bake_fluid()
    bpy.context.scene.frame_set(2)
    # A missing executable says where to set it.
    prefs.executable = str(tmp_path / "no-such-licvdb")
    try:
        with pytest.raises(RuntimeError, match="Preferences > Add-ons > licvdb"):
            bpy.ops.licvdb.bake_fluid()
    finally:
        prefs.executable = ""
    # A bake licvdb refuses (length beyond the recipe's maximum): its message, and nothing left.
    s.length = 20000.0
    with pytest.raises(RuntimeError, match="licvdb bake failed for frame 2.*length"):
        bpy.ops.licvdb.bake_fluid()
    assert not glob.glob(str(tmp_path / "out" / "*.vdb"))
    # A bake that outlives the operator's timeout is cancelled and reported; nothing is left.
    s.length = 6.0
    with pytest.raises(RuntimeError, match="longer than"):
        bpy.ops.licvdb.bake_fluid(timeout=0.02)
    assert not glob.glob(str(tmp_path / "out" / "*"))
    # Not a fluid domain.
    bpy.ops.mesh.primitive_cube_add()
    with pytest.raises(RuntimeError, match="poll"):
        bpy.ops.licvdb.bake_fluid()


def test_bake_job_cancel_leaves_no_files(tmp_path):
    """Esc in the modal operator calls BakeJob.cancel(): licvdb is interrupted (SIGINT) and
    nothing is written."""
    field = tmp_path / "big.vdb"
    run_licvdb("field", "abc", "--res", "48,48,48", "--out", field, "--quiet")
    out = tmp_path / "out"
    out.mkdir()
    recipe = {"field": {"path": str(field)}, "output": {"path": str(out / "big_lic.vdb"), "upsample": 4},
              "lic": {"length": 30, "engine": "naive"}, "threads": 1}
    job = ops_bake.BakeJob(licvdb_exe(), [("frame 1", recipe), ("frame 2", dict(recipe))])
    job.start()
    # Progress arrives as licvdb works (--progress lines), before the bake is done.
    wait_until_running(job)
    assert 0.0 < job.fraction < 0.5, (job.fraction, job.progress_seen)
    assert "frame 1 (1/2, " in job.status()
    # A generous grace (a busy machine may be slow to schedule licvdb): licvdb must stop on SIGINT
    # by itself; the kill after the grace would leave -9, not 1.
    job.cancel(grace=120.0)
    assert job.proc.returncode is not None
    assert job.proc.returncode == 1, "licvdb did not stop on SIGINT"  # "cancelled; no output written", not a kill
    assert job.cancelled and job.finished
    assert os.listdir(out) == []
    assert not os.path.exists(job.workdir)


def test_licvdb_progress_lines(tmp_path):
    """`licvdb bake --progress lines` (what the add-on runs) prints `progress FRACTION STAGE` lines
    on stderr even though it is not a terminal, ending each stage at 1."""
    import subprocess

    field = tmp_path / "f.vdb"
    run_licvdb("field", "abc", "--res", "16,16,16", "--out", field, "--quiet")
    proc = subprocess.run([licvdb_exe(), "bake", "--field", str(field), "--out", str(tmp_path / "o.vdb"),
                           "--progress", "lines", "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    lines = [l.split(" ", 2) for l in proc.stderr.splitlines() if l.startswith("progress ")]
    assert lines, proc.stderr
    fractions = [float(f) for _, f, _ in lines]
    assert all(f == -1.0 or 0.0 <= f <= 1.0 for f in fractions)
    assert fractions[-1] == 1.0
    stages = {s for _, _, s in lines}
    assert stages and all(s.strip() for s in stages)
    quiet = subprocess.run([licvdb_exe(), "bake", "--field", str(field), "--out", str(tmp_path / "q.vdb"),
                            "--progress", "lines", "--quiet"], capture_output=True, text=True)
    assert quiet.returncode == 0 and "progress" not in quiet.stderr
    bad = subprocess.run([licvdb_exe(), "bake", "--field", str(field), "--out", str(tmp_path / "b.vdb"),
                          "--progress", "dots"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--progress" in bad.stderr


def test_sequence_bake_cancel_leaves_no_files(tmp_path):
    """Esc during a sequence bake: frames already made are staged, not written, so once the
    second frame has started, cancelling still leaves nothing. Progress names the frame."""
    fields = tmp_path / "fields"
    fields.mkdir()
    run_licvdb("field", "tornado", "--res", "24,24,24", "--frames", "1,3", "--out", fields / "t_####.vdb", "--quiet")
    out = tmp_path / "out"
    out.mkdir()
    recipe = {"field": {"path": str(fields / "t_####.vdb"), "frames": [1, 3]},
              "output": {"path": str(out / "seq.vdb"), "upsample": 3},
              "lic": {"length": 16, "engine": "naive"}, "threads": 1}
    job = ops_bake.BakeJob(licvdb_exe(), [("frames 1-3", recipe)])
    job.start()
    t0 = time.monotonic()
    while not any(s.startswith("frame 2 (2/3)") for s, _ in job.progress_seen) and time.monotonic() - t0 < 120.0:
        assert not job.poll(), "the sequence finished before it could be cancelled; make it bigger"
        job.fraction
        time.sleep(0.05)
    assert any(s.startswith("frame 1 (1/3)") for s, _ in job.progress_seen), job.progress_seen[:5]
    assert any(s.startswith("frame 2 (2/3)") for s, _ in job.progress_seen)
    job.cancel()
    assert job.proc.returncode == 1
    assert os.listdir(out) == []

"""licvdb.bake_file on a CFD mesh (.vtu, through licvdb's mesh module): the mesh is baked like any
field file; without the mesh module the report says which engine lacks it and what to install."""

import json
import os

import bpy
import pytest
from mathutils import Vector

from licvdb import manifest as mf

from conftest import run_licvdb

N = 8  # cells a side of the test mesh, on [0, 1]³


def write_vtu(path, n=N):
    """An ASCII .vtu of n³ hexahedra on [0, 1]³ with a swirl about the z axis plus an updraft
    (point data "U")."""
    pts, vel = [], []
    for k in range(n + 1):
        for j in range(n + 1):
            for i in range(n + 1):
                x, y, z = i / n, j / n, k / n
                pts.append(f"{x} {y} {z}")
                vel.append(f"{-(y - 0.5)} {x - 0.5} 0.2")
    idx = lambda i, j, k: (k * (n + 1) + j) * (n + 1) + i  # noqa: E731
    conn = []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                conn += [idx(i, j, k), idx(i + 1, j, k), idx(i + 1, j + 1, k), idx(i, j + 1, k),
                         idx(i, j, k + 1), idx(i + 1, j, k + 1), idx(i + 1, j + 1, k + 1), idx(i, j + 1, k + 1)]
    cells = n ** 3
    text = f"""<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
 <UnstructuredGrid>
  <Piece NumberOfPoints="{len(pts)}" NumberOfCells="{cells}">
   <PointData><DataArray type="Float32" Name="U" NumberOfComponents="3" format="ascii">
{chr(10).join(vel)}
   </DataArray></PointData>
   <Points><DataArray type="Float32" Name="Points" NumberOfComponents="3" format="ascii">
{chr(10).join(pts)}
   </DataArray></Points>
   <Cells>
    <DataArray type="Int64" Name="connectivity" format="ascii">{" ".join(map(str, conn))}</DataArray>
    <DataArray type="Int64" Name="offsets" format="ascii">{" ".join(str(8 * (c + 1)) for c in range(cells))}</DataArray>
    <DataArray type="UInt8" Name="types" format="ascii">{" ".join(["12"] * cells)}</DataArray>
   </Cells>
  </Piece>
 </UnstructuredGrid>
</VTKFile>
"""
    path.write_text(text)
    return path


@pytest.fixture
def mesh(tmp_path):
    d = tmp_path / "cfd"
    d.mkdir()
    s = bpy.context.scene.licvdb_bake
    s.length, s.upsample = 4.0, 1
    return write_vtu(d / "swirl.vtu")


def test_bake_file_of_a_vtu_mesh(mesh):
    before = set(bpy.data.objects)
    assert bpy.ops.licvdb.bake_file(filepath=str(mesh)) == {"FINISHED"}
    new = set(bpy.data.objects) - before
    assert len(new) == 1, new
    obj = new.pop()
    assert obj.type == "VOLUME" and obj.licvdb.is_bake and obj.licvdb.source_kind == "FILE"
    assert obj.data.grids.load(), obj.data.grids.error_message
    assert "density" in {g.name for g in obj.data.grids}
    out = bpy.path.abspath(obj.data.filepath)
    assert os.path.dirname(out) == str(mesh.parent / "licvdb")
    assert mf.read_manifest(obj.licvdb.manifest).recipe["field"]["path"] == str(mesh)
    # The lattice covers the mesh's box, [0, 1]³ (voxel centres on its faces), and the band of one
    # voxel around the fluid (so trilinear sampling inside finds all 8 corners), and the object
    # adds no transform of its own beyond the import's placement.
    info = json.loads(run_licvdb("info", out, "--json"))
    density = next(g for g in info["grids"] if g["name"] == "density")
    h = density["voxel_size"][0]
    lo, hi = density["world_bbox"]
    assert lo == pytest.approx([-1.5 * h] * 3, abs=1e-6) and hi == pytest.approx([1 + 1.5 * h] * 3, abs=1e-6)
    assert obj.matrix_world.to_translation() == Vector(obj.licvdb.placement_shift)


def test_without_the_mesh_module_the_report_says_what_to_install(mesh, monkeypatch):
    monkeypatch.setenv("LICVDB_MESH_MODULE", str(mesh.parent / "no-such" / "licvdb-mesh.so"))
    before = set(bpy.data.objects)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.licvdb.bake_file(filepath=str(mesh))
    message = str(e.value)
    assert "mesh module" in message and "is missing" in message, message
    assert "full licvdb" in message, message  # the add-on's hint: which engine reads meshes
    assert set(bpy.data.objects) == before
    assert not list(mesh.parent.glob("licvdb/*.vdb")), "a failed bake leaves no file"

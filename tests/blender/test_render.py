"""A 64×64 Cycles render of an imported halo bake: lines visible, in the right place, and a gap
where a line passes behind another."""

import json

import bpy
import numpy as np
import pytest

import halo_fixture as hf
import render_util
from conftest import run_licvdb


@pytest.fixture(scope="module")
def crossing(tmp_path_factory):
    path = hf.write(tmp_path_factory.mktemp("halo"))
    # The fixture is what licvdb writes for Blender: both grids as leaf voxels, no tiles.
    info = json.loads(run_licvdb("info", path, "--json"))
    grids = {g["name"]: g for g in info["grids"]}
    assert set(grids) == {"density", "halo"}
    assert all(g["active_tiles"] == 0 for g in grids.values())
    assert grids["halo"]["active_voxels"] > grids["density"]["active_voxels"]
    return path


def test_halo_bake_gets_the_halo_look(crossing):
    """What the render below starts from, checked apart from it (it runs where Blender cannot render)."""
    assert bpy.ops.licvdb.import_bake(filepath=crossing) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.licvdb.look == "HALOS"  # a bake with a halo grid gets the halo look
    nodes = obj.active_material.node_tree.nodes
    assert "halo minus line" in nodes and nodes["halo minus line"].operation == "SUBTRACT"


@pytest.mark.renders
def test_halo_render_shows_gap(crossing, tmp_path):
    assert bpy.ops.licvdb.import_bake(filepath=crossing) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.licvdb.look == "HALOS"  # a bake with a halo grid gets the halo look
    nodes = obj.active_material.node_tree.nodes
    assert "halo minus line" in nodes and nodes["halo minus line"].operation == "SUBTRACT"
    render_util.ortho_camera_looking_down((0.5, 0.5, 0.5), 1.0)
    lum = render_util.render_luminance(tmp_path / "halo.png")
    size = lum.shape[0]
    centre = size // 2  # x = y = 0.5 is the border between pixels 31 and 32

    # Line A (front, along x): bright away from the crossing; background black.
    a_profile = lum[:, 8:20].mean(axis=1)  # mean over columns away from B, per row
    a_peak = a_profile[centre - 1:centre + 1].mean()
    background = np.concatenate([lum[:6, :6].ravel(), lum[-6:, -6:].ravel()])
    assert a_peak > 0.25, f"front line too dim: {a_peak:.3f}"
    assert background.max() < 0.02, f"background not black: {background.max():.3f}"

    # It is where it should be: the brightness centroid across the line sits at y = 0.5, i.e.
    # Cycles puts voxel (i, j, k) at (i, j, k) × voxel size like OpenVDB (to well within the
    # one-pixel shift a half-voxel error would cause).
    rows = np.arange(size) + 0.5
    band = slice(centre - 8, centre + 8)
    centroid = (rows[band] * a_profile[band]).sum() / a_profile[band].sum()
    assert centroid == pytest.approx(size / 2, abs=0.3), centroid

    # Line B (back, along y): visible far from A, dark right beside A (inside A's halo, outside
    # A's line: the gap), and it does not shine through A's core either.
    b_column = lum[:, centre - 1:centre + 1].mean(axis=1)
    far = np.concatenate([b_column[centre - 22:centre - 12], b_column[centre + 12:centre + 22]]).mean()
    # Darkest point of the back line on each side of the front line, inside the front line's
    # halo (3.5 voxels = 7 px) but outside its core (1.5 voxels = 3 px).
    beside_lo = b_column[centre - 7:centre - 3].min()
    beside_hi = b_column[centre + 3:centre + 7].min()
    beside = max(beside_lo, beside_hi)
    assert far > 0.1, f"back line too dim away from the crossing: {far:.3f}"
    assert beside < 0.3 * far, f"no gap on both sides: back line beside the front line {beside:.3f} vs far {far:.3f}"
    print(f"halo render: front line peak {a_peak:.3f}, centroid row {centroid:.2f} (expected {size / 2}), "
          f"back line far {far:.3f}, beside the front line {beside:.3f} (ratio {beside / far:.3f})")

    # Lines-only look: no gap (same pixels brighter than with halos).
    obj.licvdb.look = "LINES"
    lum2 = render_util.render_luminance(tmp_path / "lines.png")
    b2 = lum2[:, centre - 1:centre + 1].mean(axis=1)
    beside2 = max(b2[centre - 7:centre - 3].min(), b2[centre + 3:centre + 7].min())
    far2 = np.concatenate([b2[centre - 22:centre - 12], b2[centre + 12:centre + 22]]).mean()
    assert beside2 > 0.7 * far2, f"lines-only look should show the back line beside the front one: {beside2:.3f} vs {far2:.3f}"

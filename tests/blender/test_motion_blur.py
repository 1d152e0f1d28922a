"""Motion blur from a bake's ``velocity`` grid (licvdb --write-velocity): the import makes it the
volume's velocity, and a Cycles render with motion blur on streaks the spots along the flow (+x),
not across it."""

import bpy
import numpy as np
import pytest

import render_util
from conftest import run_licvdb

FPS = 4  # uniform flow of 1 world unit per second; a whole-frame shutter moves 0.25 units = 8 pixels


@pytest.fixture(scope="module")
def moving_spots(tmp_path_factory):
    d = tmp_path_factory.mktemp("blur")
    field = d / "uniform.vdb"
    run_licvdb("field", "uniform", "--res", "16,16,16", "--out", field)
    out = d / "spots.vdb"
    run_licvdb("bake", "--field", field, "--out", out, "--input", "spots", "--spacing", "7", "--radii", "1.5",
               "--length", "1", "--write-velocity", "--quiet")
    return str(out)


def test_import_sets_the_velocity_grid(moving_spots):
    assert bpy.ops.licvdb.import_bake(filepath=moving_spots) == {"FINISHED"}
    vol = bpy.context.active_object.data
    assert vol.velocity_grid == "velocity"
    assert vol.velocity_unit == "SECOND"
    assert vol.velocity_scale == pytest.approx(1.0)
    vol.grids.load()
    assert "velocity" in [g.name for g in vol.grids]


def _gradients(img):
    """Mean |∂/∂x| and |∂/∂y| of an image (columns are x, rows y)."""
    return np.abs(np.diff(img, axis=1)).mean(), np.abs(np.diff(img, axis=0)).mean()


@pytest.mark.renders
def test_motion_blur_streaks_along_the_flow(moving_spots, tmp_path):
    assert bpy.ops.licvdb.import_bake(filepath=moving_spots) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    render_util.ortho_camera_looking_down((0.0, 0.0, 0.0), 2.0)
    scene.render.use_motion_blur = False
    sharp = render_util.render_luminance(tmp_path / "sharp.png", samples=32)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 1.0
    blurred = render_util.render_luminance(tmp_path / "blurred.png", samples=32)

    assert sharp.max() > 0.2, f"the spots do not show: {sharp.max():.3f}"
    diff = np.abs(blurred - sharp).mean()
    assert diff > 0.05 * sharp.mean(), f"motion blur changed nothing ({diff:.4f} vs mean {sharp.mean():.4f})"
    # Blur along x smooths the image along x: its x-gradients drop much more than its y-gradients.
    sx, sy = _gradients(sharp)
    bx, by = _gradients(blurred)
    along, across = bx / sx, by / sy
    print(f"gradient ratio blurred/sharp: along the flow {along:.3f}, across {across:.3f}")
    assert along < 0.8 * across, f"the blur is not along the flow: x {along:.3f}, y {across:.3f}"

"""The Blender render and the reference raycaster (`licvdb render`) of the same halo bake agree
in where the lines are, and both show the gap where the back line passes behind the front one."""

import json

import bpy
import numpy as np
import pytest
from mathutils import Matrix, Vector

import halo_fixture as hf
import render_util
from conftest import run_licvdb

SIZE = 64


def load_luminance(path):
    """Luminance of an image file, row 0 at the bottom (Blender's pixel order)."""
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, img.channels)
    finally:
        bpy.data.images.remove(img)
    return 0.2126 * px[..., 0] + 0.7152 * px[..., 1] + 0.0722 * px[..., 2]


def camera_from_json(cam):
    """A Blender camera from the `blender` block of `licvdb render --json`."""
    b = cam["blender"]
    data = bpy.data.cameras.new("reference camera")
    data.type = b["type"]
    data.sensor_fit = b["sensor_fit"]
    if b["type"] == "ORTHO":
        data.ortho_scale = b["ortho_scale"]
    else:
        data.angle_y = b["angle_y"]
    data.clip_start, data.clip_end = 1e-3, 1e4
    obj = bpy.data.objects.new("reference camera", data)
    bpy.context.collection.objects.link(obj)
    obj.matrix_world = Matrix(b["matrix_world"])
    bpy.context.scene.camera = obj
    return obj


def pixel_of(cam, point):
    """(row from the bottom, column) of a world point in the orthographic camera `cam` (JSON)."""
    d = Vector(point) - Vector(cam["position"])
    w, h = cam["image_size"]
    col = (d.dot(Vector(cam["right"])) / cam["ortho_width"] + 0.5) * w
    row = (d.dot(Vector(cam["up"])) / cam["ortho_height"] + 0.5) * h
    return int(row), int(col)


def gap_ratio(lum, cam):
    """Brightness of the back line B right beside the front line A (2.5 voxels from A's axis:
    outside A's core, inside its halo) over B's brightness 10 voxels away."""
    v = hf.VOXEL

    def b_at(dy):
        vals = []
        for sign in (-1, 1):
            r, c = pixel_of(cam, (0.5, 0.5 + sign * dy, hf.B[0][2]))
            vals.append(lum[r, c - 1:c + 1].mean())
        return np.mean(vals)

    return b_at(2.5 * v) / b_at(10 * v)


@pytest.mark.renders
@pytest.mark.reads_blender_vdb  # licvdb renders the crossing written by OpenVDB's Python module
def test_blender_matches_reference_raycaster(tmp_path):
    crossing = hf.write(tmp_path)
    # Scene-linear EXR from both renderers: no display transform in the comparison.
    ref_path = tmp_path / "reference.exr"
    summary = json.loads(run_licvdb("render", crossing, "--out", ref_path, "--size", f"{SIZE},{SIZE}",
                                    "--view", "top", "--ortho", "--json", "--quiet"))
    cam = summary["camera"]
    assert cam["projection"] == "orthographic" and summary["halos"] is True
    ref = load_luminance(ref_path)
    assert ref.shape == (SIZE, SIZE)

    assert bpy.ops.licvdb.import_bake(filepath=crossing) == {"FINISHED"}
    camera_from_json(cam)
    ours = render_util.render_luminance(tmp_path / "blender.exr", size=SIZE)

    # Where the lines are, independent of the two renderers' transfer functions: Blender's line
    # mask (brighter than a quarter of its bright level) against the same number of the
    # reference's brightest pixels.
    mine = ours > 0.25 * np.percentile(ours, 99)
    k = int(mine.sum())
    theirs = ref >= np.sort(ref.ravel())[-k]
    iou = (mine & theirs).sum() / max(1, (mine | theirs).sum())
    # Rank correlation of the luminance (also insensitive to monotone transfer functions).
    rank = lambda a: np.argsort(np.argsort(a.ravel(), kind="stable"), kind="stable").astype(np.float64)
    spearman = np.corrcoef(rank(ours), rank(ref))[0, 1]
    pearson = np.corrcoef(ours.ravel(), ref.ravel())[0, 1]
    gap_ours, gap_ref = gap_ratio(ours, cam), gap_ratio(ref, cam)
    print(f"blender vs reference raycaster ({SIZE}×{SIZE}, top, ortho): line-mask IoU {iou:.3f} "
          f"({k} px), luminance rank correlation {spearman:.3f}, linear correlation {pearson:.3f}; "
          f"gap (back line beside / far from the front line) blender {gap_ours:.3f}, reference {gap_ref:.3f}")
    assert iou > 0.7, f"line masks disagree: IoU {iou:.3f}"
    assert spearman > 0.7, f"luminance ranks disagree: {spearman:.3f}"
    assert gap_ours < 0.5 and gap_ref < 0.5, (gap_ours, gap_ref)

"""tools/blender_render.py: renders a bake through the add-on in a separate Blender process."""

import json
import os
import subprocess

import bpy
import numpy as np
import pytest

from conftest import run_licvdb

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOOL = os.path.join(ROOT, "tools", "blender_render.py")


def luminance(path):
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, img.channels)
    finally:
        bpy.data.images.remove(img)
    return 0.2126 * px[..., 0] + 0.7152 * px[..., 1] + 0.0722 * px[..., 2]


@pytest.mark.renders
def test_blender_render_tool_matches_the_reference_camera(tmp_path):
    field, bake = tmp_path / "abc.vdb", tmp_path / "spots.vdb"
    run_licvdb("field", "abc", "--res", "16,16,16", "--out", field, "--quiet")
    run_licvdb("bake", "--field", field, "--out", bake, "--input", "spots", "--spacing", "6", "--length", "8",
               "--roi", "speed", "--roi-range", "2,4", "--quiet")
    ref = tmp_path / "ref.png"
    summary = json.loads(run_licvdb("render", bake, "--out", ref, "--size", "48,48", "--json", "--quiet"))
    (tmp_path / "ref.json").write_text(json.dumps(summary))
    out = tmp_path / "cycles.png"
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1", "-P", TOOL,
                           "--", str(bake), "--out", str(out), "--camera", str(tmp_path / "ref.json"),
                           "--size", "48", "--samples", "8"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "blender_render: wrote" in proc.stdout
    ours, theirs = luminance(out), luminance(ref)
    assert ours.shape == theirs.shape == (48, 48)
    lit_ours, lit_ref = ours > 0.1, theirs > 0.1
    assert 0.02 < lit_ours.mean() < 0.9, lit_ours.mean()
    # Same camera, same bake: the lit pixels overlap (IoU of the line masks; test_compare has
    # the exact figure at higher resolution).
    iou = (lit_ours & lit_ref).sum() / max(1, (lit_ours | lit_ref).sum())
    print(f"blender_render.py vs licvdb render (48², same camera): line-mask IoU {iou:.3f}")
    assert iou > 0.5, iou


def test_blender_render_tool_rejects_bad_arguments(tmp_path):
    field, bake = tmp_path / "abc.vdb", tmp_path / "lic.vdb"
    run_licvdb("field", "abc", "--res", "8,8,8", "--out", field, "--quiet")
    run_licvdb("bake", "--field", field, "--out", bake, "--upsample", "1", "--length", "4", "--quiet")
    # Bad arguments end Blender with a non-zero exit and the tool's usage message.
    bad = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1", "-P", TOOL,
                          "--", str(bake)], capture_output=True, text=True, timeout=120)
    assert bad.returncode != 0
    assert "--out" in bad.stderr

"""Bake presets (presets.py): the shipped presets set the bake settings and the look of new bakes,
a bake after a preset works (a relative region of interest resolved against the field's top
speed), a re-bake keeps its object's look, and a user's preset is saved, listed, applied and
removed through Blender's preset operators."""

import json
import os

import bpy
import pytest

from licvdb import manifest as mf
from licvdb import presets

from conftest import run_licvdb
from bake_util import small_field
from test_bake_file import bake

SHIPPED = {  # lines seeded where the flow is faster than a quarter of its top speed (any field)
    "Streamlines with halos by speed": dict(input_type="spots", kernel="box", roi_scalar="speed", roi_mode="pre",
                                            roi_relative=True, loop_frames=1, color_scalar="speed", look_set=True,
                                            look="HALOS"),
    "Dense LIC in a region": dict(input_type="noise", roi_scalar="speed", roi_relative=True, roi_mode="post",
                                  loop_frames=1, look_set=True, look="LINES"),
    "Comet loop": dict(input_type="spots", kernel="box", loop_frames=24, roi_scalar="speed", look="HALOS"),
    "Tapered exp loop": dict(input_type="spots", kernel="exp", loop_frames=24, roi_scalar="speed", look="LINES"),
}


@pytest.fixture
def user_presets(tmp_path, monkeypatch):
    """The user's preset folder in tmp_path (AddPresetBase and the menu ask bpy.utils.user_resource)."""
    real = bpy.utils.user_resource

    def user_resource(kind, path="", create=False):
        if kind == "SCRIPTS" and path.startswith("presets"):
            d = tmp_path / "scripts" / path
            if create:
                d.mkdir(parents=True, exist_ok=True)
            return str(d)
        return real(kind, path=path, create=create)

    monkeypatch.setattr(bpy.utils, "user_resource", user_resource)
    return tmp_path / "scripts" / "presets" / "licvdb" / "bake"


def apply(path):
    assert bpy.ops.script.execute_preset(filepath=str(path), menu_idname=presets.LICVDB_MT_bake_presets.bl_idname) \
        == {"FINISHED"}


def values(s):
    return {n: (tuple(getattr(s, n)) if n == "roi_range" else getattr(s, n)) for n in presets.PRESET_SETTINGS}


def test_registered_and_listed(user_presets):
    assert hasattr(bpy.types, "LICVDB_MT_bake_presets") and hasattr(bpy.ops.licvdb, "bake_preset_add")
    assert sorted(presets.shipped_presets()) == sorted(SHIPPED)
    assert presets.preset_dirs()[0] == presets.SHIPPED_DIR


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_each_shipped_preset_sets_every_setting(name):
    s = bpy.context.scene.licvdb_bake
    s.roi_scalar, s.loop_frames, s.kernel, s.look_set, s.seed_object = "vorticity", 7, "exp", False, None
    s.output_dir, s.threads = "//somewhere", 3
    path = presets.shipped_presets()[name]
    with open(path, encoding="utf-8") as f:
        text = f.read()
    assert all(f"s.{n} = " in text for n in presets.PRESET_SETTINGS), "a preset sets every setting it covers"
    apply(path)
    assert presets.LICVDB_MT_bake_presets.bl_label == name
    for key, value in SHIPPED[name].items():
        assert getattr(s, key) == value, (name, key)
    assert (s.output_dir, s.threads) == ("//somewhere", 3), "where and how a bake runs is not the preset's"


def test_bake_after_the_streamlines_preset_gets_its_look(tmp_path):
    field = small_field(tmp_path)
    s = bpy.context.scene.licvdb_bake
    apply(presets.shipped_presets()["Streamlines with halos by speed"])
    s.upsample, s.length, s.spot_spacing = 1, 6.0, 4.0  # (small and quick)
    s.look_brightness, s.look_halo_strength = 2.5, 3.0
    obj = bake(field)
    man = mf.read_manifest(obj.licvdb.manifest)
    assert man.recipe["input"]["type"] == "spots" and man.recipe["input"]["halo_scale"] == 2.0
    assert man.recipe["color"]["scalar"] == "speed"
    assert "halo" in obj.licvdb.grid_names.split(",")
    lic = obj.licvdb
    assert (lic.look, lic.brightness, lic.halo_strength) == ("HALOS", 2.5, 3.0)
    # A re-bake keeps the object's look (the user's), not the settings'.
    lic.look, lic.brightness = "LINES", 0.7
    assert bpy.ops.licvdb.rebake() == {"FINISHED"}
    assert (obj.licvdb.look, obj.licvdb.brightness) == ("LINES", pytest.approx(0.7))


def test_dense_region_preset_resolves_the_range_against_the_top_speed(tmp_path):
    field = small_field(tmp_path)
    top = json.loads(run_licvdb("info", field, "--json"))["grids"][0]["value_range"][1]
    s = bpy.context.scene.licvdb_bake
    apply(presets.shipped_presets()["Dense LIC in a region"])
    s.upsample, s.length = 1, 4.0
    obj = bake(field)
    roi = mf.read_manifest(obj.licvdb.manifest).recipe["roi"]
    assert roi["scalar"] == "speed" and roi["mode"] == "post"
    assert roi["range"] == pytest.approx([0.4 * top, 1.0 * top], rel=1e-5)
    lic = obj.licvdb
    assert (lic.look, lic.brightness, lic.line_absorption) == ("LINES", pytest.approx(0.6), pytest.approx(1.0))
    # In the field's units instead: the range as given.
    s.roi_relative, s.roi_range = False, (1.0, 2.0)
    roi = mf.read_manifest(bake(field).licvdb.manifest).recipe["roi"]
    assert roi["range"] == [1.0, 2.0]


def test_relative_region_on_a_field_licvdb_info_cannot_read(tmp_path):
    """A .npy field: licvdb info reads only .vdb, so the report says to give the range in units."""
    import numpy as np
    path = tmp_path / "f.npy"
    np.save(path, np.ones((8, 8, 8, 3), dtype=np.float32))
    s = bpy.context.scene.licvdb_bake
    s.roi_scalar, s.roi_relative, s.length, s.upsample = "speed", True, 4.0, 1
    with pytest.raises(RuntimeError, match="region of interest.*turn off Fraction of top speed"):
        bpy.ops.licvdb.bake_file(filepath=str(path))
    assert not os.path.exists(tmp_path / "licvdb") or not os.listdir(tmp_path / "licvdb")


def test_user_preset_saved_applied_and_removed(user_presets):
    s = bpy.context.scene.licvdb_bake
    s.length, s.kernel, s.decay, s.roi_scalar, s.roi_range = 33.0, "exp", 0.8, "speed", (0.25, 0.75)
    s.look_set, s.look_brightness = True, 4.0
    saved = values(s)
    assert bpy.ops.licvdb.bake_preset_add(name="My jet") == {"FINISHED"}
    path = user_presets / "My_jet.py"
    assert path.is_file()
    assert str(user_presets) in presets.preset_dirs()
    s.length, s.kernel, s.roi_scalar, s.roi_range, s.look_set = 5.0, "box", "NONE", (0.1, 0.2), False
    apply(path)
    assert values(s) == {k: (pytest.approx(v) if isinstance(v, (float, tuple)) else v) for k, v in saved.items()}
    assert presets.LICVDB_MT_bake_presets.bl_label == "My jet"
    assert bpy.ops.licvdb.bake_preset_add(remove_active=True) == {"FINISHED"}
    assert not path.exists() and presets.find_user_preset("My jet") is None


def test_shipped_presets_cannot_be_removed(user_presets):
    path = presets.shipped_presets()["Comet loop"]
    apply(path)
    assert bpy.ops.licvdb.bake_preset_add(remove_active=True) == {"CANCELLED"}
    assert os.path.isfile(path)

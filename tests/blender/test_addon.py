"""The add-on as a package: registration, preferences, the import menu, the zip, the manifest."""

import os
import tomllib
import types

import addon_utils
import bpy
import pytest

import licvdb
from licvdb import manifest as mf
from licvdb import material, prefs

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_registered():
    assert hasattr(bpy.ops.licvdb, "import_bake") and hasattr(bpy.ops.licvdb, "bake_fluid")
    assert hasattr(bpy.types.Object, "licvdb") and hasattr(bpy.types.Scene, "licvdb_bake")
    assert "LICVDB_PT_look" in dir(bpy.types) and "LICVDB_PT_bake" in dir(bpy.types)
    draw_funcs = [f.__name__ for f in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()]
    assert "menu_import" in draw_funcs


def test_unregister_and_register_again():
    addon_utils.disable("licvdb", default_set=True)
    assert not hasattr(bpy.types.Object, "licvdb")
    addon_utils.enable("licvdb", default_set=True)
    assert hasattr(bpy.types.Object, "licvdb")


def test_executable_preference():
    p = bpy.context.preferences.addons["licvdb"].preferences
    assert p.executable == ""
    assert prefs.find_executable() == os.environ["LICVDB_EXECUTABLE"]
    p.executable = "/nonexistent/licvdb"
    try:
        assert prefs.find_executable() is None
        assert "Preferences > Add-ons > licvdb" in prefs.missing_executable_message()
    finally:
        p.executable = ""


def test_bl_info_and_extension_manifest():
    assert licvdb.bl_info["blender"] <= (3, 4, 0)
    with open(os.path.join(ROOT, "blender_addon", "licvdb", "blender_manifest.toml"), "rb") as f:
        m = tomllib.load(f)
    assert m["id"] == "licvdb" and m["type"] == "add-on"
    assert m["blender_version_min"] == "4.2.0"
    assert tuple(int(v) for v in m["version"].split(".")) == licvdb.bl_info["version"]


def test_sequence_and_manifest_helpers(tmp_path):
    for i in (1, 2, 3, 5):
        (tmp_path / f"x_{i:04d}.vdb").write_bytes(b"")
    files = mf.sequence_files(str(tmp_path / "x_0002.vdb"))
    assert [os.path.basename(f) for f in files] == ["x_0001.vdb", "x_0002.vdb", "x_0003.vdb"]
    assert mf.frame_number("loop_0012.vdb") == 12 and mf.frame_number("still.vdb") is None
    assert mf.manifest_candidates("/a/loop_0003.vdb") == ["/a/loop_0003.licvdb.json", "/a/loop_0003.json",
                                                         "/a/loop.licvdb.json", "/a/loop.json"]
    assert mf.manifest_path("/a/jet.vdb") == "/a/jet.licvdb.json"
    assert mf.bake_name("/a/jet.licvdb.json") == "jet" and mf.bake_name("/a/jet.json") == "jet"
    with pytest.raises(mf.ManifestError, match="not a licvdb manifest"):
        mf.parse_manifest({"foo": 1}, "m.json")


def test_ramp_points_thinned_and_linear():
    pts = [(i / 40, i / 40, 0.5, 1.0) for i in range(41)]
    ramp = material.ramp_points(pts)
    assert len(ramp) == material.MAX_RAMP_ELEMENTS
    assert ramp[0][0] == 0.0 and ramp[-1][0] == 1.0
    assert ramp[0][1][1] == pytest.approx(0.2140, abs=1e-3)  # sRGB 0.5 → linear


class RecordingLayout:
    """Stands in for a UILayout (background mode draws no UI): records what a panel draws and
    checks that every property it shows exists."""

    def __init__(self, log):
        self.log = log
        self.enabled = True

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, f"panel shows missing property {name!r}"
        self.log.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **kw):
        assert name in data.bl_rna.properties, f"panel shows missing property {name!r}"
        assert search_name in search_data.bl_rna.properties, search_name
        self.log.append(("prop", name))

    def operator(self, idname, **kw):
        module, op = idname.split(".")
        assert hasattr(getattr(bpy.ops, module), op), idname
        self.log.append(("operator", idname))
        return types.SimpleNamespace()  # (the operator's properties, which a panel may set)

    def menu(self, idname, **kw):
        assert hasattr(bpy.types, idname), f"panel shows unregistered menu {idname!r}"
        self.log.append(("menu", idname))

    def label(self, text="", **kw):
        self.log.append(("label", text))

    def template_color_ramp(self, data, name, **kw):
        assert name in data.bl_rna.properties
        self.log.append(("ramp", name))

    def _sub(self, *a, **kw):
        return RecordingLayout(self.log)

    column = row = box = _sub


def draw_panel(cls, context):
    log = []

    class Fake:
        layout = RecordingLayout(log)

    assert cls.poll(context) if hasattr(cls, "poll") else True
    cls.draw(Fake(), context)
    return log


def test_panels_draw(bakes):
    assert bpy.ops.licvdb.import_bake(filepath=str(bakes["still"])) == {"FINISHED"}
    ctx = bpy.context
    log = draw_panel(bpy.types.LICVDB_PT_look, ctx)
    shown = {n for kind, n in log if kind == "prop"}
    assert {"look", "brightness", "halo_strength", "color_source"} <= shown
    assert ("ramp", "color_ramp") in log  # the bake has a colormap: its ramp is editable here
    log = draw_panel(bpy.types.LICVDB_PT_bake, ctx)
    assert ("operator", "licvdb.bake_fluid") in log
    assert any(kind == "label" and "smoke domain" in n for kind, n in log)  # a volume is active

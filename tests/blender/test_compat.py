"""Blender-version guards (licvdb/compat.py) and the 4.x/5.0 changes behind them (issue 17).

Each guard's branches run in every Blender by forcing the predicate with monkeypatch; a branch
that needs an API this Blender lacks runs against a stand-in property of the same name and type
(registered in the test, removed after it). Where this Blender has the real thing (5.2.2:
``volume_biased``, node trees on new materials, deprecated ``use_nodes``), the test checks the
real thing. docs/blender.md, "Tested versions", lists what ran in 3.4.1, 4.3.2 and 5.2.2.
"""

import ast
import os
import re
import warnings

import bpy
import pytest

from licvdb import compat, material, ops_import, props

from test_addon import draw_panel

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def import_still(bakes):
    assert bpy.ops.licvdb.import_bake(filepath=str(bakes["still"])) == {"FINISHED"}
    return bpy.context.active_object


def test_version_checks_only_in_compat():
    """Every version or feature check of the add-on is a named predicate in compat.py."""
    pkg = os.path.join(ROOT, "blender_addon", "licvdb")
    found = []
    for name in sorted(os.listdir(pkg)):
        if name.endswith(".py") and name != "compat.py":
            with open(os.path.join(pkg, name), encoding="utf-8") as f:
                src = f.read()
            found += [f"{name}: {m}" for m in re.findall(r"bpy\.app\.version\b|hasattr\([^)]*\)", src)]
    assert not found, found


def test_file_handler_guard():
    """4.1+ file handlers: absent in 3.4, so only the operator is registered here. (The other
    branch needs bpy.types.FileHandler: not testable in 3.4.)"""
    assert compat.has_file_handler() == hasattr(bpy.types, "FileHandler")
    if not compat.has_file_handler():
        assert [c.__name__ for c in ops_import.classes] == ["LICVDB_OT_import_bake"]


def test_extension_user_folder_guard():
    """4.2+ extensions have a user folder (engine.py copies a read-only bundled engine there)."""
    assert compat.has_extension_user_folder() == (bpy.app.version >= (4, 2, 0))


# --- use_nodes (deprecated in 5.0) ----------------------------------------------------------------

def test_use_nodes_guard_matches_this_blender():
    assert compat.node_use_nodes_deprecated() == (bpy.app.version >= (5, 0, 0))


#: Blender 5.0+ gives every new material and world a node tree, deprecates use_nodes (reading or
#: writing it warns) and always renders the tree (measured in 5.2.2; 3.4.1 and 4.3.2 do neither).
REAL_5 = bpy.app.version >= (5, 0, 0)


def use_nodes_warnings(caught):
    return [str(w.message) for w in caught if "use_nodes" in str(w.message)]


@pytest.mark.older_branch
@pytest.mark.parametrize("deprecated", [False, True], ids=["before-5.0", "5.0"])
def test_ensure_node_tree_creates_a_missing_tree(monkeypatch, deprecated):
    monkeypatch.setattr(compat, "node_use_nodes_deprecated", lambda: deprecated)
    for idblock in (bpy.data.materials.new("m"), bpy.data.worlds.new("w")):
        if REAL_5:
            # 5.0+ creates the tree with the data-block: there is none to create; it is kept.
            before = idblock.node_tree
            assert before is not None
            tree = compat.ensure_node_tree(idblock)
            assert tree == before and tree == idblock.node_tree and len(tree.nodes) > 0
            continue
        assert idblock.node_tree is None  # (3.4 and 4.3 create no tree with a new material or world)
        tree = compat.ensure_node_tree(idblock)
        assert tree is not None and tree == idblock.node_tree and len(tree.nodes) > 0


@pytest.mark.older_branch
def test_ensure_node_tree_before_5_0_turns_nodes_on(monkeypatch):
    """Before 5.0 a material whose nodes are off renders without its tree: turn them on."""
    monkeypatch.setattr(compat, "node_use_nodes_deprecated", lambda: False)
    mat = bpy.data.materials.new("m")
    mat.use_nodes = True
    mat.use_nodes = False  # the tree stays, unused
    assert mat.node_tree is not None
    compat.ensure_node_tree(mat)
    assert mat.use_nodes


def test_ensure_node_tree_5_0_leaves_use_nodes_alone(monkeypatch):
    """5.0: nodes are always on and reading or writing use_nodes warns: a material with a tree is
    neither written nor read. Before 5.0 (where the branch is forced) the untouched flag stays
    False, which shows nothing wrote it; in 5.0+ (the real branch) no use_nodes deprecation
    warning is raised, which shows nothing read or wrote it."""
    monkeypatch.setattr(compat, "node_use_nodes_deprecated", lambda: True)
    mat = bpy.data.materials.new("m")
    world = bpy.data.worlds.new("w")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # (setting up warns in 5.0+, not the add-on)
        for idblock in (mat, world):
            idblock.use_nodes = True
            idblock.use_nodes = False
    bpy.context.scene.world = world
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compat.ensure_node_tree(mat)
        # The material builder goes through the same guard: it builds the tree and leaves the flag.
        nodes = material.build_lic_material(mat, ["density"], material.Look())
        # And so does the world in setup_render.
        material.setup_render(bpy.context.scene)
    assert nodes["emission"].name in mat.node_tree.nodes
    bg = world.node_tree.nodes["Background"]
    assert tuple(bg.inputs["Color"].default_value)[:3] == (0.0, 0.0, 0.0)
    if REAL_5:
        assert use_nodes_warnings(caught) == [], use_nodes_warnings(caught)
    else:
        assert mat.use_nodes is False
        assert world.use_nodes is False


def test_setup_render_without_a_world(monkeypatch):
    bpy.context.scene.world = None
    material.setup_render(bpy.context.scene)
    world = bpy.context.scene.world
    assert world is not None and world.use_nodes
    assert world.node_tree.nodes["Background"].inputs["Strength"].default_value == 0.0


def test_panel_reads_the_node_tree_not_use_nodes(bakes):
    """The look panel finds the colour ramp through the node tree: in 5.0 use_nodes is always
    True, and here a material whose flag is off still shows its ramp."""
    obj = import_still(bakes)
    obj.active_material.use_nodes = False
    log = draw_panel(bpy.types.LICVDB_PT_look, bpy.context)
    assert ("ramp", "color_ramp") in log


# --- Cycles volume_biased (5.0) ---------------------------------------------------------------------

@pytest.fixture
def stand_in_volume_biased():
    """Cycles' 5.0 ``volume_biased`` (BoolProperty, default False) added to this Blender's Cycles
    scene settings for the test only; in a Blender that has it, the real one."""
    cls = type(bpy.context.scene.cycles)  # cycles.properties.CyclesRenderSettings
    added = "volume_biased" not in cls.bl_rna.properties
    if added:
        cls.volume_biased = bpy.props.BoolProperty(name="Biased", default=False)
    yield
    if added:
        del cls.volume_biased


def test_volume_biased_guard_follows_the_property():
    scene = bpy.context.scene
    assert compat.has_volume_biased(scene) == ("volume_biased" in scene.cycles.bl_rna.properties)


def test_setup_render_with_this_blenders_volume_settings(bakes):
    """Before 5.0 (3.4.1, 4.3.2): ray marching is the only volume algorithm; the step rate is set
    and nothing else is needed. 5.0+ (5.2.2): the real Biased option exists, off by default, and
    setup_render turns it on."""
    scene = bpy.context.scene
    assert compat.has_volume_biased(scene) == REAL_5, "volume_biased exists exactly in 5.0+"
    if REAL_5:
        assert scene.cycles.volume_biased is False  # 5.0's default: null scattering
    material.setup_render(scene)
    assert scene.cycles.volume_step_rate == pytest.approx(0.5)
    assert scene.cycles.volume_max_steps >= 1024
    if REAL_5:
        assert scene.cycles.volume_biased is True
    import_still(bakes)
    log = draw_panel(bpy.types.LICVDB_PT_look, bpy.context)
    assert not any(kind == "label" and "step rate" in text for kind, text in log)


def test_setup_render_turns_volume_biased_on(stand_in_volume_biased, bakes):
    scene = bpy.context.scene
    assert compat.has_volume_biased(scene) and scene.cycles.volume_biased is False
    import_still(bakes)  # imports set up the render
    assert scene.cycles.volume_biased is True
    assert scene.cycles.volume_step_rate == pytest.approx(0.5)
    log = draw_panel(bpy.types.LICVDB_PT_look, bpy.context)
    assert not any(kind == "label" and "step rate" in text for kind, text in log)
    # Turned off by the user (or imported without "Set up render"): the panel says so.
    scene.cycles.volume_biased = False
    log = draw_panel(bpy.types.LICVDB_PT_look, bpy.context)
    assert any(kind == "label" and "ignores the volume step rate" in text for kind, text in log)
    assert any(kind == "label" and "Biased" in text for kind, text in log)


# --- look settings: plain assignment, one rebuild ----------------------------------------------------

def test_import_sets_the_look_with_one_rebuild(bakes, monkeypatch):
    """The import writes look, brightness and line absorption with plain assignment (5.0 no longer
    supports dict-style writes to bpy.props storage) and still rebuilds the material once."""
    calls = []
    real = material.build_lic_material

    def counting(mat, grids, look):
        calls.append(look)
        return real(mat, grids, look)

    monkeypatch.setattr(material, "build_lic_material", counting)
    obj = import_still(bakes)
    assert len(calls) == 1
    assert (calls[0].brightness, calls[0].line_absorption) == pytest.approx(ops_import.DENSE_LOOK)
    assert props._rebuild_suspended == 0
    obj.licvdb.brightness = 2.0  # after the import, each change rebuilds again
    assert len(calls) == 2 and calls[1].brightness == pytest.approx(2.0)


def test_rebuild_suspended_is_released_on_error(bakes):
    obj = import_still(bakes)
    with pytest.raises(ValueError):
        with props.rebuild_suspended():
            obj.licvdb.brightness = 5.0
            raise ValueError("boom")
    assert props._rebuild_suspended == 0
    obj.licvdb.brightness = 4.0
    strength = obj.active_material.node_tree.nodes["line brightness"].inputs[1].default_value
    assert strength == pytest.approx(4.0 / obj.licvdb.voxel_size, rel=1e-5)


def dict_style_offenders(src, name):
    """Subscripts with a string key on the add-on's property groups (``obj.licvdb``,
    ``scene.licvdb_bake``, or a name the add-on binds to one: s, settings, prefs)."""
    out = []
    for node in ast.walk(ast.parse(src)):
        if not (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
                and isinstance(node.slice.value, str)):
            continue
        target = node.value
        if ((isinstance(target, ast.Attribute) and target.attr in ("licvdb", "licvdb_bake"))
                or (isinstance(target, ast.Name) and target.id in ("s", "settings", "prefs"))):
            out.append(f"{name}:{node.lineno}: {ast.unparse(node)}")
    return out


def test_no_dict_style_access_to_addon_properties():
    """5.0 no longer supports dict-style access to properties defined with bpy.props."""
    offenders = []
    pkg = os.path.join(ROOT, "blender_addon", "licvdb")
    for name in sorted(os.listdir(pkg)):
        if name.endswith(".py"):
            with open(os.path.join(pkg, name), encoding="utf-8") as f:
                offenders += dict_style_offenders(f.read(), name)
    assert not offenders, offenders
    # The check is not vacuous: it flags the forms the add-on used to have, and only those.
    old = 's["look"] = 1\nobj.licvdb["brightness"] = 2\nx = recipe["lic"]\n"""s["look"]"""\n'
    assert len(dict_style_offenders(old, "old.py")) == 2

"""The add-on's choice lists (props.py: kernels, colour scalars, colormaps) against the engine's
own tables (`licvdb help --json`), so a kernel, scalar or colormap added to licvdb or renamed
cannot be missed or offered wrongly by the add-on."""

import json

import bpy

from licvdb import props

from conftest import run_licvdb


def engine_choices():
    return json.loads(run_licvdb("help", "--json"))


def enum_ids(prop_name):
    return [i.identifier for i in bpy.context.scene.licvdb_bake.bl_rna.properties[prop_name].enum_items]


def test_kernels_and_colormaps_are_the_engines():
    c = engine_choices()
    assert enum_ids("kernel") == c["kernels"]
    assert sorted(enum_ids("colormap")) == sorted(c["colormaps"])


def test_every_derived_scalar_is_offered_and_the_rest_are_fluid_grids():
    c = engine_choices()
    offered = [i[0] for i in props.SCALARS if i[0] != "NONE"]
    assert set(c["scalars"]) <= set(offered), set(c["scalars"]) - set(offered)
    # The others are a smoke simulation's own float grids, which licvdb reads from the field file.
    assert set(offered) - set(c["scalars"]) == {"density", "temperature"}
    assert set(enum_ids("color_scalar")) == {"NONE", *offered}


def test_the_grids_the_addon_reads_are_the_engines():
    """Every grid the add-on reads (grids.py) is in licvdb's output-grid table with the same value
    type, and every grid the table says the add-on uses is one it reads."""
    from licvdb import grids

    table = {g["name"]: g for g in engine_choices()["grids"]}
    for name, value_type in grids.USED.items():
        assert name in table, name
        assert table[name]["type"] == value_type, (name, table[name]["type"])
    used = {n for n, g in table.items() if g["blender"] != "not used"}
    assert used == set(grids.USED), used ^ set(grids.USED)

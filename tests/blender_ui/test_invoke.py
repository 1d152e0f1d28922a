"""licvdb.import_bake's (and licvdb.bake_file's) invoke, as File > Import starts it: in a window,
not nested in a Python operator call (``undo=True``), so Blender restores the operator's
last-used properties."""

import bpy


def volumes():
    return sorted(o.name for o in bpy.context.scene.objects if o.type == "VOLUME")


def test_files_given_by_the_caller_import_at_once(bakes, view3d):
    """Drag and drop (a file handler) and scripts pass the files: invoke imports them directly."""
    result = bpy.ops.licvdb.import_bake("INVOKE_DEFAULT", True, directory=str(bakes),
                                        files=[{"name": "first.vdb"}])
    assert result == {"FINISHED"}
    assert volumes() == ["first"]


def test_second_import_from_the_menu_opens_the_file_browser(bakes, view3d):
    """Issue 17: the second File > Import in a session re-imported the previous file without
    asking, because Blender restores the last filepath and ``invoke`` tested ``self.filepath``."""
    first = str(bakes / "first.vdb")
    assert bpy.ops.licvdb.import_bake("INVOKE_DEFAULT", True, filepath=first) == {"FINISHED"}
    assert volumes() == ["first"]
    # Blender kept this import's filepath as the operator's last-used value…
    last = bpy.context.window_manager.operator_properties_last("licvdb.import_bake")
    assert last.filepath == first
    # …and restores it when the menu starts the operator again (no filepath given): the file
    # browser must open (RUNNING_MODAL) and nothing be imported yet.
    result = bpy.ops.licvdb.import_bake("INVOKE_DEFAULT", True)
    assert result == {"RUNNING_MODAL"}, f"{result}: the previous file was imported again"
    assert volumes() == ["first"]


def test_bake_from_flow_file_menu_opens_the_file_browser(bakes, view3d):
    """File > Import > Bake LIC from flow file… starts licvdb.bake_file without a file: invoke
    opens the file browser (the bake starts, modal, once a file is chosen) and bakes nothing yet."""
    result = bpy.ops.licvdb.bake_file("INVOKE_DEFAULT", True)
    assert result == {"RUNNING_MODAL"}, result
    assert volumes() == []
    assert not (bakes / "licvdb").exists()

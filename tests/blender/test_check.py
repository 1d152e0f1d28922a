"""licvdb.check: a corrupt .vdb, or a .vdb its manifest does not describe, never reaches
Blender's reader; the import is cancelled with the reason."""

import json
import os
import shutil
import struct

import bpy
import pytest

from licvdb import check, ops_import
from licvdb import manifest as mf


def lie_in_first_blosc_block(data: bytes) -> bytes:
    """The first blosc block of the file made to claim 2038 more bytes than it holds (the kind of
    lie that made OpenVDB 10 overrun a leaf buffer: issue 19)."""
    for i in range(8, len(data) - 16):
        stored = struct.unpack_from("<q", data, i - 8)[0]
        nbytes, cbytes = struct.unpack_from("<I", data, i + 4)[0], struct.unpack_from("<I", data, i + 12)[0]
        if data[i] == 2 and stored == cbytes and 16 < cbytes and nbytes > 0:
            out = bytearray(data)
            struct.pack_into("<I", out, i + 4, nbytes + 2038)
            return bytes(out)
    raise AssertionError("no blosc block found")


def volumes():
    return {v.name for v in bpy.data.volumes}


def test_corrupt_vdb_is_refused_before_blender_reads_it(bakes, tmp_path):
    bad = tmp_path / "downloaded.vdb"  # no manifest beside it: a foreign file
    bad.write_bytes(lie_in_first_blosc_block(bakes["still"].read_bytes()))
    before = volumes()
    with pytest.raises(check.FileCheckError) as err:
        ops_import.import_bake(bpy.context, str(bad))
    msg = str(err.value)
    assert "downloaded.vdb: it is not an intact .vdb file" in msg
    assert "blosc block claims" in msg, msg  # licvdb's reason, shown to the user
    assert volumes() == before, "no volume may be created for a refused file"
    # The operator cancels with the reason as its error report (a RuntimeError in background mode).
    with pytest.raises(RuntimeError, match="blosc block claims"):
        bpy.ops.licvdb.import_bake(filepath=str(bad))
    assert volumes() == before


def test_vdb_that_its_manifest_does_not_describe_is_refused(bakes, tmp_path):
    # A bake's manifest beside another bake's .vdb (what two bakes to one output used to leave).
    # (Separate directories: replacing a file an open Blender has loaded is not supported.)
    still_json = mf.manifest_path(str(bakes["still"]))
    good, bad = tmp_path / "good", tmp_path / "bad"
    for d in (good, bad):
        d.mkdir()
        shutil.copy(still_json, d / "still.licvdb.json")
    shutil.copy(bakes["still"], good / "still.vdb")
    man = json.loads((good / "still.licvdb.json").read_text())
    assert man["sha256"]["still.vdb"] == check.sha256_of(str(good / "still.vdb"))
    assert ops_import.import_bake(bpy.context, str(good / "still.vdb")) is not None  # matching: imported
    shutil.copy(os.path.join(os.path.dirname(str(bakes["loop"])), "loop_0001.vdb"), bad / "still.vdb")
    before = volumes()
    with pytest.raises(check.FileCheckError) as err:
        ops_import.import_bake(bpy.context, str(bad / "still.vdb"))
    assert "is not the file its manifest" in str(err.value)
    with pytest.raises(RuntimeError, match="is not the file its manifest"):
        bpy.ops.licvdb.import_bake(filepath=str(bad / "still.vdb"))
    assert volumes() == before


def test_intact_foreign_vdb_is_checked_and_imported(bakes, tmp_path):
    shutil.copy(bakes["still"], tmp_path / "plain.vdb")  # no manifest: licvdb info --check runs
    obj = ops_import.import_bake(bpy.context, str(tmp_path / "plain.vdb"))
    assert obj.data.grids.load()

"""Checking .vdb files before Blender's own reader sees them.

Blender reads a .vdb with its OpenVDB, which trusts the sizes stored in the file: a corrupt or
crafted file can crash Blender (and lose unsaved work). Before an import hands a file to
Blender, ``check_bake`` verifies

1. for a licvdb bake whose manifest carries checksums (``"sha256": {file name: hex}``), that
   every file is the one the manifest describes (another bake to the same output, a copy from
   elsewhere, or damage in transit would differ), and
2. for every file, that ``licvdb info --check`` passes: licvdb walks the file's whole structure,
   then reads every grid in a child process (see docs/inputs.md), and exits 2 with the reason
   for a corrupt file.

Without a licvdb executable (prefs.locate_executable: the add-on preferences,
``$LICVDB_EXECUTABLE``, the engine the Linux extension carries, PATH, …) the import is refused
with what to install or set, unless the user turned on the preference "Import without checking"
(then step 2 is skipped with a note on the console; step 1 still runs).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess

from . import engine, prefs

#: Seconds one ``licvdb info --check`` may take (it has its own per-file limit as well).
CHECK_TIMEOUT = 600


class FileCheckError(Exception):
    """A file that must not be given to Blender's reader; the message says why."""


def sha256_of(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def verify_checksums(manifest_path: str, files) -> None:
    """Raise FileCheckError if a file's SHA-256 differs from the one its manifest records.
    Manifests without checksums (bakes before licvdb 0.1's issue 19) are not checked."""
    try:
        with open(manifest_path, encoding="utf-8") as f:
            sums = json.load(f).get("sha256") or {}
    except (OSError, ValueError):
        return  # manifest.read_manifest reports unreadable manifests
    for path in files:
        expected = sums.get(os.path.basename(path))
        if expected and sha256_of(path) != expected:
            raise FileCheckError(
                f"{path} is not the file its manifest {manifest_path} describes (its checksum differs: "
                "another bake wrote the same output, or the file was replaced or damaged); re-run the bake")


def check_vdb(path: str, executable: str) -> None:
    """Run ``licvdb info --check --json`` on ``path``; raise FileCheckError with licvdb's reason
    if the file is not intact (exit 2) or the check itself fails."""
    try:
        proc = subprocess.run([executable, "info", "--check", "--json", path], capture_output=True, text=True,
                              timeout=CHECK_TIMEOUT, stdin=subprocess.DEVNULL, env=engine.engine_env())
    except subprocess.TimeoutExpired:
        raise FileCheckError(f"checking {path} took longer than {CHECK_TIMEOUT} s; not importing it") from None
    except OSError as e:
        raise FileCheckError(f"cannot run {executable} to check {path}: {e}") from None
    if proc.returncode == 0:
        return
    reason = ""
    try:
        reason = json.loads(proc.stdout).get("error", "")
    except ValueError:
        pass
    if not reason:
        err = proc.stderr.strip()
        reason = err.splitlines()[0] if err else f"exit {proc.returncode}"
    if proc.returncode == 2:
        raise FileCheckError(f"cannot read {path}: it is not an intact .vdb file, so it is not given to "
                             f"Blender's reader: {reason}")
    raise FileCheckError(f"checking {path} failed (licvdb exit {proc.returncode}): {reason}")


def check_bake(context, files, man=None) -> None:
    """Check every file of a bake before it is imported (see the module docstring).
    ``man`` is the bake's manifest (manifest.Manifest) or None. Raises FileCheckError."""
    if man is not None:
        verify_checksums(man.path, files)
    exe = prefs.find_executable(context)
    if exe is None:
        if not prefs.import_unchecked_allowed(context):
            raise FileCheckError(f"not importing: the files cannot be checked before Blender reads them (a corrupt "
                                 f".vdb can crash Blender). {prefs.missing_executable_message(context)}; or, at your "
                                 "own risk, turn on \"Import without checking\" there")
        print(f"licvdb: {prefs.missing_executable_message(context)}; importing without checking the files "
              "(\"Import without checking\" is on)")
        return
    for path in files:
        check_vdb(path, exe)

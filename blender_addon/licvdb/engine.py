"""The licvdb engine that the Linux extension carries, and the environment licvdb runs in.

The platform build of the extension (``scripts/package-addon --engine``) holds a relocatable
licvdb (``scripts/bundle``) in the folder ``engine/`` of the package:

- ``bin/licvdb``: the launcher (runs the program through the bundle's own loader),
- ``lib/``: that loader and every shared library, ``libexec/licvdb/licvdb``: the program,
  ``share/licvdb/``: resources,
- ``EXECUTABLES``: the files that need the executable bit (one path a line, relative to
  ``engine/``), ``VERSION``: the engine's version.

Blender installs extensions with Python's ``zipfile``, which drops the executable bits.
``find_engine`` gives them back (u+x, go+rx) before first use. Where the package folder is not
writable (a system repository), it copies the engine once into the extension's user folder
(``bpy.utils.extension_path_user``, Blender 4.2+) as ``engine-VERSION/`` and sets the bits
there; a stamp file written last marks a complete copy, so an interrupted copy is made again.

``engine_env()`` is the environment for every licvdb the add-on runs (bundled or not).
"""

import os
import shutil
import stat
import sys

import bpy

from . import compat

#: The engine's folder inside the package, and its launcher inside that folder.
ENGINE_DIR = "engine"
LAUNCHER = os.path.join("bin", "licvdb")

#: Written last into a copy of the engine (copy_engine): its content is the source's fingerprint.
STAMP = ".licvdb-engine-complete"

#: The package folder whose ``engine/`` is looked at; tests point it elsewhere.
PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))

#: The only platform the bundled engine runs on (Blender's name for it, as in the manifest).
PLATFORM = "linux-x64"

#: chmod u+x, go+rx
EXEC_BITS = stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH

#: Removed from the environment licvdb runs in (engine_env): they are set for the Blender
#: process (by its launcher, a snap or flatpak, or a studio's wrapper) and would misdirect
#: licvdb or a program it starts.
#: - LD_LIBRARY_PATH, LD_PRELOAD: point at Blender's own libraries (its OpenVDB, TBB, OpenImageIO,
#:   Mesa); a licvdb that loads those gets other versions than it was built with. The bundle's
#:   launcher unsets them as well, but a licvdb on PATH has no launcher.
#: - PYTHONPATH, PYTHONHOME, PYTHONSAFEPATH, PYTHONUSERBASE, PYTHONNOUSERSITE, PYTHONSTARTUP:
#:   meant for Blender's Python (its version, its site-packages); any Python run by a child
#:   process would take them.
#: - OCIO, OCIO_ACTIVE_DISPLAYS, OCIO_ACTIVE_VIEWS, OCIO_INACTIVE_COLORSPACES: name Blender's
#:   colour configuration (one the OpenColorIO licvdb links may not read: Blender 4.x's needs
#:   OCIO 2.2+) and filter its displays and views; licvdb's raycaster uses a config of its own.
BLENDER_ONLY_VARIABLES = ("LD_LIBRARY_PATH", "LD_PRELOAD",
                          "PYTHONPATH", "PYTHONHOME", "PYTHONSAFEPATH", "PYTHONUSERBASE", "PYTHONNOUSERSITE",
                          "PYTHONSTARTUP",
                          "OCIO", "OCIO_ACTIVE_DISPLAYS", "OCIO_ACTIVE_VIEWS", "OCIO_INACTIVE_COLORSPACES")


class EngineError(Exception):
    """A bundled engine folder that is incomplete; the message says what is wrong."""


def engine_env() -> dict:
    """A copy of ``os.environ`` for running licvdb, without BLENDER_ONLY_VARIABLES."""
    env = dict(os.environ)
    for name in BLENDER_ONLY_VARIABLES:
        env.pop(name, None)
    return env


def launcher(engine_dir: str) -> str:
    return os.path.join(engine_dir, LAUNCHER)


def bundled_engine_dir(package_dir: str | None = None) -> str | None:
    """The package's ``engine/`` folder if it holds a launcher, else None."""
    d = os.path.join(package_dir or PACKAGE_DIR, ENGINE_DIR)
    return d if os.path.isfile(launcher(d)) else None


def executables(engine_dir: str) -> list:
    """Absolute paths of the files ``EXECUTABLES`` lists. Raises EngineError if the list is
    unreadable, names a path outside the folder, or a file that is missing."""
    listing = os.path.join(engine_dir, "EXECUTABLES")
    try:
        with open(listing, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise EngineError(f"{listing} cannot be read ({e.strerror}); reinstall the extension") from None
    root = os.path.abspath(engine_dir)
    paths = []
    for rel in (line.strip() for line in lines):
        if not rel or rel.startswith("#"):
            continue
        path = os.path.normpath(os.path.join(root, rel))
        if os.path.isabs(rel) or not path.startswith(root + os.sep):
            raise EngineError(f"{listing}: \"{rel}\" is not a path inside the engine folder")
        if not os.path.isfile(path):
            raise EngineError(f"{listing} lists {rel}, which is missing; reinstall the extension")
        paths.append(path)
    return paths


def _needs_bits(engine_dir: str) -> list:
    """The launcher and every file EXECUTABLES lists, once each."""
    return list(dict.fromkeys([os.path.abspath(launcher(engine_dir)), *executables(engine_dir)]))


def is_ready(engine_dir: str) -> bool:
    """Whether this process may run the launcher and every file EXECUTABLES lists."""
    return all(os.access(p, os.X_OK) for p in _needs_bits(engine_dir))


def restore_bits(engine_dir: str) -> None:
    """chmod u+x,go+rx the launcher and every file EXECUTABLES lists. Raises OSError
    (PermissionError where the files are not ours) or EngineError."""
    for path in _needs_bits(engine_dir):
        mode = stat.S_IMODE(os.stat(path).st_mode)
        if mode & EXEC_BITS != EXEC_BITS:
            os.chmod(path, mode | EXEC_BITS)


def version(engine_dir: str) -> str:
    """The engine's VERSION, or "unknown"."""
    try:
        with open(os.path.join(engine_dir, "VERSION"), encoding="utf-8") as f:
            return f.read().strip() or "unknown"
    except OSError:
        return "unknown"


def fingerprint(engine_dir: str) -> str:
    """What identifies an engine's build for copy_engine: its version and the sizes of its
    executables (a rebuild under the same version differs in them)."""
    root = os.path.abspath(engine_dir)
    sizes = [f"{os.path.relpath(p, root)} {os.path.getsize(p)}" for p in executables(engine_dir)]
    return "\n".join([f"version {version(engine_dir)}", *sizes]) + "\n"


def _read_text(path: str) -> str | None:
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except OSError:
        return None


def copy_engine(src: str, dest_parent: str) -> str:
    """Copy the engine folder ``src`` into ``dest_parent/engine-VERSION`` and restore the bits
    there; returns the copy's folder. A copy whose stamp matches ``src`` (fingerprint) is reused;
    one without it (interrupted, or of another build) is removed and made again.
    Raises OSError or EngineError."""
    name = "engine-" + "".join(c if c.isalnum() or c in "._+-" else "_" for c in version(src))
    dest = os.path.join(dest_parent, name)
    stamp = os.path.join(dest, STAMP)
    want = fingerprint(src)
    if _read_text(stamp) == want and is_ready(dest):
        return dest
    if os.path.lexists(dest):
        shutil.rmtree(dest)
    os.makedirs(dest_parent, exist_ok=True)
    shutil.copytree(src, dest, symlinks=True, ignore=shutil.ignore_patterns(STAMP))
    restore_bits(dest)
    with open(stamp + ".tmp", "w", encoding="utf-8") as f:
        f.write(want)
    os.replace(stamp + ".tmp", stamp)  # last: the copy is complete
    return dest


def user_engine_parent():
    """``(folder, "")``: the extension's user folder (created); or ``(None, why)`` where there is
    none (Blender before 4.2; an add-on not installed as an extension, ``bl_ext.REPO.licvdb``)."""
    if not compat.has_extension_user_folder():
        return None, f"Blender {bpy.app.version_string} has no extension user folder (4.2+)"
    if not (__package__ or "").startswith("bl_ext."):
        return None, f"the add-on ({__package__}) is not installed as an extension, so it has no user folder"
    return bpy.utils.extension_path_user(__package__, create=True), ""


def _runnable(engine_dir: str, user_dir: str | None):
    """(launcher, "") once the engine at ``engine_dir`` can run, in place or as a user copy;
    (None, reason) otherwise. Raises OSError or EngineError."""
    if is_ready(engine_dir):
        return launcher(engine_dir), ""
    if os.access(os.path.dirname(engine_dir), os.W_OK):
        try:
            restore_bits(engine_dir)
            return launcher(engine_dir), ""
        except PermissionError:
            pass  # files of another user in a folder we may write: copy them as below
    parent, why = (user_dir, "") if user_dir else user_engine_parent()
    if parent is None:
        return None, (f"the engine in {engine_dir} lost its executable bits and its folder is read-only; "
                      f"there is nowhere to copy it to: {why}")
    return launcher(copy_engine(engine_dir, parent)), ""


def find_engine(package_dir: str | None = None, user_dir: str | None = None):
    """The bundled engine's launcher, made runnable: ``(path, "")``, or ``(None, reason)``.

    ``package_dir`` defaults to PACKAGE_DIR; ``user_dir`` is where a read-only engine is copied
    (default: the extension's user folder, user_engine_parent)."""
    engine_dir = bundled_engine_dir(package_dir)
    if engine_dir is None:
        return None, "none in this add-on (the Linux extension zip, licvdb-VERSION-blender-linux-x64.zip, carries one)"
    if not sys.platform.startswith("linux") or os.uname().machine not in ("x86_64", "amd64"):
        return None, f"the bundled engine is for {PLATFORM}, not {sys.platform} {os.uname().machine}"
    try:
        return _runnable(engine_dir, user_dir)
    except (OSError, EngineError) as e:
        return None, f"the bundled engine in {engine_dir} cannot be made runnable: {e}"


def missing_module_hint(message: str) -> str:
    """What to do when licvdb's ``message`` says one of its modules (mesh: VTK's CFD readers;
    image: OIIO/OCIO) is missing: the extension's own engine is built without them."""
    for module, what, instead in (
            ("mesh module", "CFD meshes (.vtu, .vtk, OpenFOAM, PLOT3D …) need",
             ", or convert the mesh to a .vdb with `licvdb convert` where the full licvdb is installed"),
            ("image module", "images need", "")):
        if module in message and "is missing" in message:
            return (f"the licvdb engine in use has no {module}, which {what}: install the full licvdb bundle "
                    f"(licvdb-VERSION-linux-x86_64.tar.xz) and choose its bin/licvdb in the add-on's "
                    f"preferences{instead}")
    return ""

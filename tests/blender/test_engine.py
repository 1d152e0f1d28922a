"""The engine the Linux extension carries (licvdb/engine.py), and imports without any licvdb.

The engine folders here are real: ``engine/bin/licvdb`` is a copy of the licvdb under test (a
dynamically linked program that runs from any path), and so is ``engine/libexec/licvdb/licvdb``
(where the bundle keeps the program behind its launcher); both are listed in
``engine/EXECUTABLES``. Blender's extension
installer unpacks with Python's zipfile, which drops executable bits: the tests unpack the same
way. A read-only package folder is made read-only for real (``chattr +i`` as root, who ignores
permission bits; mode 0555 otherwise)."""

import os
import shutil
import stat
import subprocess
import zipfile

import bpy
import pytest

from licvdb import check, compat, engine, ops_import, prefs

from conftest import licvdb_exe
from test_executable import LICVDB, clean_env, draw_preferences, link_licvdb  # noqa: F401 (clean_env: a fixture)

EXECUTABLES = ("bin/licvdb", "libexec/licvdb/licvdb")


def make_engine(package_dir, version="0.1.0"):
    """``package_dir/engine``: the licvdb under test as a bundled engine. Returns its folder."""
    eng = package_dir / "engine"
    for rel in EXECUTABLES:
        (eng / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(LICVDB, eng / rel)
    (eng / "EXECUTABLES").write_text("".join(f"{p}\n" for p in EXECUTABLES))
    (eng / "VERSION").write_text(f"{version}\n")
    return eng


def unpack_like_blender(src_dir, dest_dir):
    """Zip ``src_dir`` and unpack it into ``dest_dir`` with zipfile, as Blender installs extensions."""
    archive = shutil.make_archive(str(dest_dir) + "-zip", "zip", src_dir)
    with zipfile.ZipFile(archive) as z:
        z.extractall(dest_dir)
    return dest_dir


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def assert_runnable(eng):
    for rel in EXECUTABLES:
        assert mode(eng / rel) & 0o755 == 0o755, f"{rel}: {oct(mode(eng / rel))}, expected u+x,go+rx"
    proc = subprocess.run([str(eng / "bin" / "licvdb"), "--version"], capture_output=True, text=True,
                          env=engine.engine_env())
    assert proc.returncode == 0 and proc.stdout.startswith("licvdb "), (proc.returncode, proc.stdout, proc.stderr)


def test_dropped_executable_bits_are_restored_and_the_engine_comes_before_path(clean_env, monkeypatch):
    staged = clean_env / "staged"
    make_engine(staged)
    pkg = unpack_like_blender(staged, clean_env / "package")
    eng = pkg / "engine"
    assert all(mode(eng / rel) & 0o111 == 0 for rel in EXECUTABLES), "zipfile kept the executable bits"
    on_path = link_licvdb(clean_env / "bin")
    monkeypatch.setenv("PATH", str(clean_env / "bin"))
    path, source, tried = prefs.locate_executable()
    assert (path, source) == (str(eng / "bin" / "licvdb"), "bundled engine"), (path, source, tried)
    assert path != on_path
    assert_runnable(eng)
    # The preferences say which licvdb is used, and its version (licvdb --version).
    version = subprocess.run([LICVDB, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    labels = draw_preferences(bpy.context)
    assert f"Using: {path} (bundled engine)" in labels and f"Version: {version}" in labels, labels


def test_preference_and_environment_variable_come_before_the_engine(clean_env, monkeypatch):
    make_engine(clean_env / "package")
    monkeypatch.setenv("LICVDB_EXECUTABLE", LICVDB)
    assert prefs.locate_executable()[:2] == (LICVDB, "$LICVDB_EXECUTABLE")
    chosen = link_licvdb(clean_env / "chosen")
    bpy.context.preferences.addons["licvdb"].preferences.executable = chosen
    assert prefs.locate_executable()[:2] == (chosen, "preferences")


def test_version_is_run_once_per_executable(clean_env):
    exe = link_licvdb(clean_env / "bin")
    first = prefs.executable_version(exe)
    assert first.startswith("licvdb "), first
    key = next(k for k in prefs._versions if k[0] == exe)
    prefs._versions[key] = "cached"  # a second call reads the cache, it does not run licvdb again
    assert prefs.executable_version(exe) == "cached"
    del prefs._versions[key]


def test_copy_in_the_user_folder_is_made_once_and_redone_when_incomplete(tmp_path):
    src = make_engine(tmp_path / "package")
    for rel in EXECUTABLES:
        os.chmod(src / rel, 0o644)
    user = tmp_path / "user"
    copy = engine.copy_engine(str(src), str(user))
    assert copy == str(user / "engine-0.1.0")
    assert_runnable(user / "engine-0.1.0")
    assert all(mode(src / rel) == 0o644 for rel in EXECUTABLES), "the source must be left as it is"
    stamp = user / "engine-0.1.0" / engine.STAMP
    assert stamp.is_file()
    marker = user / "engine-0.1.0" / "marker"
    marker.write_text("")
    assert engine.copy_engine(str(src), str(user)) == copy and marker.exists(), "a complete copy is reused"
    stamp.unlink()  # as if the copy had been interrupted: it is made again
    assert engine.copy_engine(str(src), str(user)) == copy
    assert not marker.exists() and stamp.is_file()
    assert_runnable(user / "engine-0.1.0")
    marker.write_text("")
    with open(src / "libexec" / "licvdb" / "licvdb", "ab") as f:
        f.write(b"\0" * 16)  # another build of the same version: copied again
    assert engine.copy_engine(str(src), str(user)) == copy and not marker.exists()


def make_read_only(path):
    """Make the folder ``path`` read-only for this process; returns the undo function."""
    if os.geteuid() != 0:
        os.chmod(path, 0o555)
        return lambda: os.chmod(path, 0o755)
    if shutil.which("chattr") is None:
        pytest.skip("running as root without chattr (e2fsprogs): no way to make a folder read-only")
    proc = subprocess.run(["chattr", "+i", str(path)], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"running as root, and chattr +i fails here ({proc.stderr.strip()}): no read-only folder")
    return lambda: subprocess.run(["chattr", "-i", str(path)], check=True)


@pytest.fixture
def read_only_package(tmp_path):
    """A package folder holding an engine without its executable bits, made read-only."""
    pkg = tmp_path / "package"
    eng = make_engine(pkg)
    for rel in EXECUTABLES:
        os.chmod(eng / rel, 0o644)
    undo = [make_read_only(eng / d) for d in ("bin", "libexec/licvdb")] + [make_read_only(eng), make_read_only(pkg)]
    assert not os.access(pkg, os.W_OK)
    yield pkg
    for u in reversed(undo):
        u()


def test_read_only_package_runs_a_copy_in_the_user_folder(read_only_package, tmp_path):
    user = tmp_path / "user"
    path, why = engine.find_engine(str(read_only_package), str(user))
    assert path == str(user / "engine-0.1.0" / "bin" / "licvdb"), why
    assert_runnable(user / "engine-0.1.0")
    assert all(mode(read_only_package / "engine" / rel) == 0o644 for rel in EXECUTABLES)
    assert engine.find_engine(str(read_only_package), str(user)) == (path, "")


def test_read_only_package_without_a_user_folder_says_why(read_only_package):
    """Loaded as a legacy add-on (here; and Blender before 4.2 has no extension user folder)."""
    path, why = engine.find_engine(str(read_only_package))
    assert path is None
    assert "read-only" in why and "nowhere to copy it to" in why, why
    assert ("(4.2+)" in why) == (not compat.has_extension_user_folder()), why


def test_incomplete_engine_is_reported(tmp_path):
    eng = make_engine(tmp_path / "package")
    (eng / "EXECUTABLES").write_text("bin/licvdb\nlib/ld-linux-x86-64.so.2\n")
    path, why = engine.find_engine(str(tmp_path / "package"))
    assert path is None and "lists lib/ld-linux-x86-64.so.2, which is missing" in why, why
    (eng / "EXECUTABLES").write_text("../../escape\n")
    path, why = engine.find_engine(str(tmp_path / "package"))
    assert path is None and "is not a path inside the engine folder" in why, why


BLENDER_ONLY = {"LD_LIBRARY_PATH": "/opt/blender/lib", "LD_PRELOAD": "/opt/blender/lib/libjemalloc.so",
                "PYTHONPATH": "/opt/blender/4.2/python/lib", "PYTHONHOME": "/opt/blender/4.2/python",
                "PYTHONSAFEPATH": "1", "OCIO": "/opt/blender/4.2/datafiles/colormanagement/config.ocio"}


def test_engine_env_removes_blenders_variables(monkeypatch):
    for k, v in BLENDER_ONLY.items():
        monkeypatch.setenv(k, v)
    monkeypatch.setenv("LICVDB_READ_TIMEOUT", "30")
    env = engine.engine_env()
    assert not set(BLENDER_ONLY) & set(env), sorted(set(BLENDER_ONLY) & set(env))
    assert env["PATH"] == os.environ["PATH"] and env["LICVDB_READ_TIMEOUT"] == "30"
    assert all(os.environ[k] == v for k, v in BLENDER_ONLY.items()), "os.environ itself must not change"


def test_licvdb_runs_clean_under_a_poisoned_blender_environment(bakes, tmp_path, monkeypatch):
    """With LD_LIBRARY_PATH naming a broken copy of a library licvdb links and LD_PRELOAD a
    missing one, licvdb started with os.environ fails to load; the add-on's check and bake start
    it with engine_env and work."""
    libs = subprocess.run(["ldd", licvdb_exe()], capture_output=True, text=True, check=True).stdout
    lib = next(l.split()[0] for l in libs.splitlines() if "libtbb" in l or "libopenvdb" in l)
    poison = tmp_path / "blender-lib"
    poison.mkdir()
    (poison / lib).write_bytes(b"not a library")
    monkeypatch.setenv("LD_LIBRARY_PATH", str(poison))
    monkeypatch.setenv("LD_PRELOAD", str(poison / "libmissing.so"))
    raw = subprocess.run([licvdb_exe(), "--version"], capture_output=True, text=True)
    assert raw.returncode != 0, "the poisoned environment should break licvdb (the control of this test)"
    check.check_vdb(str(bakes["still"]), licvdb_exe())
    obj = ops_import.import_bake(bpy.context, str(bakes["still"]))
    assert obj.data.grids.load()
    assert prefs.executable_version(licvdb_exe()).startswith("licvdb ")


def volumes():
    return {v.name for v in bpy.data.volumes}


def test_import_without_any_licvdb_is_refused_unless_allowed(clean_env, bakes):
    p = bpy.context.preferences.addons["licvdb"].preferences
    assert prefs.find_executable() is None and not p.import_unchecked
    before = volumes()
    with pytest.raises(check.FileCheckError) as err:
        ops_import.import_bake(bpy.context, str(bakes["still"]))
    msg = str(err.value)
    for part in ("cannot be checked", "a corrupt .vdb can crash Blender", "licvdb-VERSION-blender-linux-x64.zip",
                 "Preferences > Add-ons > licvdb", "Import without checking"):
        assert part in msg, (part, msg)
    with pytest.raises(RuntimeError, match="Import without checking"):
        bpy.ops.licvdb.import_bake(filepath=str(bakes["still"]))
    assert volumes() == before
    p.import_unchecked = True
    try:
        assert bpy.ops.licvdb.import_bake(filepath=str(bakes["still"])) == {"FINISHED"}
    finally:
        p.import_unchecked = False
    assert bpy.context.active_object.data.grids.load()
    assert "density" in {g.name for g in bpy.context.active_object.data.grids}


def test_unpacked_platform_zip_imports_with_its_own_engine(clean_env, bakes, tmp_path, monkeypatch):
    """scripts/package-addon --engine's zip, unpacked as Blender does: with no licvdb anywhere
    else, the add-on runs its engine (bits given back) and imports through its check."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    bundle = make_engine(tmp_path / "bundle")
    proc = subprocess.run([os.path.join(root, "scripts", "package-addon"), "--engine", str(bundle),
                           str(tmp_path / "zips")], capture_output=True, text=True,
                          env=dict(os.environ, PATH=os.defpath))  # (clean_env's PATH is empty)
    assert proc.returncode == 0, proc.stderr
    (zip_path,) = (tmp_path / "zips").glob("licvdb-*-blender-linux-x64.zip")
    pkg = clean_env / "installed"
    with zipfile.ZipFile(zip_path) as z:
        z.extractall(pkg)
    monkeypatch.setattr(engine, "PACKAGE_DIR", str(pkg))
    path, source, _ = prefs.locate_executable()
    assert (path, source) == (str(pkg / "engine" / "bin" / "licvdb"), "bundled engine")
    assert bpy.ops.licvdb.import_bake(filepath=str(bakes["still"])) == {"FINISHED"}
    assert "density" in bpy.context.active_object.licvdb.grid_names.split(",")

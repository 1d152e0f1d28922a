"""The add-on's zips (scripts/package-addon): the 4.2+ extension zip's layout and manifest, the
Linux extension zip that carries an engine (``--engine BUNDLE_DIR``), and the legacy zip
installed and enabled the 3.x way (Preferences > Add-ons > Install…, which 4.2+ keeps as
"Install legacy Add-on").

The extension zip is checked here against the rules of Blender 4.2's extension tooling
(docs/blender.md lists them), so that Blender 3.4 checks it too; test_extension.py installs it
for real with ``blender --command extension validate`` / ``install-file`` in 4.2+.
"""

import ast
import os
import re
import subprocess
import textwrap
import tomllib
import zipfile

import bpy
import pytest

import licvdb


ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PKG = os.path.join(ROOT, "blender_addon", "licvdb")

# Blender 4.2's manifest rules (its extension tooling, blender_ext.py, and the manual's tag list).
TERSE_MAX = 64
PERMISSION_KEYS = {"files", "network", "clipboard", "camera", "microphone"}
ADDON_TAGS = {"3D View", "Add Curve", "Add Mesh", "Animation", "Bake", "Camera", "Compositing",
              "Development", "Game Engine", "Geometry Nodes", "Grease Pencil", "Import-Export", "Lighting",
              "Material", "Modeling", "Mesh", "Node", "Object", "Paint", "Pipeline", "Physics", "Render",
              "Rigging", "Scene", "Sculpt", "Sequencer", "System", "Text Editor", "Tracking",
              "User Interface", "UV"}
PLATFORMS = {"windows-x64", "windows-arm64", "macos-x64", "macos-arm64", "linux-x64"}
SEMVER = re.compile(r"^(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(-[0-9A-Za-z.-]+)?(\+[0-9A-Za-z.-]+)?$")


def terse_error(value):
    """Blender's rule for a tagline or a permission's reason, or None if it holds."""
    if not isinstance(value, str) or not value.strip():
        return "a non-empty string expected"
    if value != value.strip():
        return "no leading/trailing white space expected"
    if len(value) > TERSE_MAX:
        return f"at most {TERSE_MAX} characters expected, found {len(value)}"
    if not (value[-1].isalnum() or value[-1] in ")]}"):
        return "must not end with punctuation"
    return None


def manifest_errors(m):
    """Every way ``m`` (a decoded blender_manifest.toml) breaks the 4.2 schema (1.0.0)."""
    errors = []
    required = {"schema_version": str, "id": str, "version": str, "name": str, "tagline": str,
                "maintainer": str, "type": str, "license": list, "blender_version_min": str}
    for key, ty in required.items():
        if key not in m:
            errors.append(f"missing {key}")
        elif not isinstance(m[key], ty):
            errors.append(f"{key} must be a {ty.__name__}")
    if errors:
        return errors
    if not SEMVER.match(m["schema_version"]) or not SEMVER.match(m["version"]):
        errors.append("schema_version and version must be semantic versions")
    pid = m["id"]
    if not pid.isidentifier() or "__" in pid or pid.startswith("_") or pid.endswith("_"):
        errors.append(f"id {pid!r} is not a valid extension id")
    for key in ("name", "maintainer"):
        if m[key] != m[key].strip() or not m[key].strip():
            errors.append(f"{key} must be non-empty without surrounding white space")
    if (e := terse_error(m["tagline"])) is not None:
        errors.append(f"tagline: {e}")
    if m["type"] not in {"add-on", "theme"}:
        errors.append(f"type {m['type']!r}")
    parts = m["blender_version_min"].split(".")
    if not all(p.isdigit() for p in parts) or tuple(int(p) for p in parts) < (4, 2, 0):
        errors.append(f"blender_version_min {m['blender_version_min']!r} must be 4.2.0 or later")
    if not m["license"] or not all(isinstance(x, str) and x.startswith("SPDX:") for x in m["license"]):
        errors.append("license must be a non-empty list of SPDX:… identifiers")
    for tag in m.get("tags", []):
        if tag not in ADDON_TAGS:
            errors.append(f"tag {tag!r} is not one of Blender's add-on tags")
    platforms = m.get("platforms", ["linux-x64"])  # optional: absent = every platform
    if not isinstance(platforms, list) or not platforms or not set(platforms) <= PLATFORMS:
        errors.append(f"platforms {platforms!r} must be a non-empty list of {sorted(PLATFORMS)}")
    perms = m.get("permissions", {})
    if not isinstance(perms, dict):
        errors.append("permissions must be a table")
    else:
        for key, why in perms.items():
            if key not in PERMISSION_KEYS:
                errors.append(f"permission {key!r}")
            elif (e := terse_error(why)) is not None:
                errors.append(f"permission {key}: {e}")
    return errors


@pytest.fixture(scope="module")
def zips(tmp_path_factory):
    out = tmp_path_factory.mktemp("zips")
    proc = subprocess.run([os.path.join(ROOT, "scripts", "package-addon"), str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    ext, legacy = out / "licvdb-blender-extension.zip", out / "licvdb-blender-addon.zip"
    assert ext.is_file() and legacy.is_file(), proc.stdout
    return {"extension": ext, "legacy": legacy}


def package_files():
    """The package's files relative to it (the shipped bake presets in presets/bake/ too), sorted."""
    out = []
    for base, dirs, names in os.walk(PKG):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        out += [os.path.relpath(os.path.join(base, f), PKG).replace(os.sep, "/") for f in names
                if f.endswith((".py", ".toml"))]
    return sorted(out)


def test_extension_zip_has_the_package_at_its_root(zips):
    names = zipfile.ZipFile(zips["extension"]).namelist()
    assert "blender_manifest.toml" in names and "__init__.py" in names
    assert sorted(names) == package_files(), "the package's files, flat at the zip's root, nothing else"
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]


def test_legacy_zip_has_the_package_folder(zips):
    names = zipfile.ZipFile(zips["legacy"]).namelist()
    assert sorted(names) == ["licvdb/" + f for f in package_files()]
    # The shipped bake presets (presets.py reads them in place) are in both zips.
    shipped = sorted(n for n in names if n.startswith("licvdb/presets/bake/") and n.endswith(".py"))
    assert len(shipped) >= 4 and "licvdb/presets/bake/Comet_loop.py" in shipped, shipped


def test_extension_manifest_is_valid(zips):
    with zipfile.ZipFile(zips["extension"]) as z:
        m = tomllib.loads(z.read("blender_manifest.toml").decode("utf-8"))
    assert manifest_errors(m) == []
    assert m["id"] == "licvdb" and m["type"] == "add-on"
    assert tuple(int(v) for v in m["version"].split(".")) == licvdb.bl_info["version"]


def test_manifest_checker_catches_bad_manifests():
    """The checker above fails on what Blender 4.2 rejects (so a passing check means something)."""
    with open(os.path.join(PKG, "blender_manifest.toml"), "rb") as f:
        good = tomllib.load(f)
    bad = [dict(good, tagline="Ends with a period."), dict(good, id="lic__vdb"), dict(good, type="addon"),
           dict(good, blender_version_min="4.1.0"), dict(good, tags=["Flow"]), dict(good, license="GPL"),
           dict(good, permissions={"files": "x" * 65}), {k: v for k, v in good.items() if k != "maintainer"},
           dict(good, platforms=["linux"]), dict(good, platforms="linux-x64"), dict(good, platforms=[])]
    for m in bad:
        assert manifest_errors(m), m


BUNDLE = {"bin/licvdb": b"#!/bin/sh\nexec \"$(dirname \"$0\")/../lib/ld-linux-x86-64.so.2\" \"$@\"\n",
          "lib/ld-linux-x86-64.so.2": b"loader", "lib/libopenvdb.so.10.0": b"library",
          "libexec/licvdb/licvdb": b"program", "share/licvdb/ocio/config.ocio": b"ocio_profile_version: 2\n",
          "EXECUTABLES": b"bin/licvdb\nlib/ld-linux-x86-64.so.2\nlibexec/licvdb/licvdb\n"}


def make_bundle(d, version):
    """A small stand-in for scripts/bundle's folder (layout only: nothing in it is run)."""
    for rel, content in {**BUNDLE, "VERSION": f"{version}\n".encode()}.items():
        path = d / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)
    for rel in ("bin/licvdb", "lib/ld-linux-x86-64.so.2", "libexec/licvdb/licvdb"):
        os.chmod(d / rel, 0o755)
    (d / "share" / "licvdb" / "__pycache__").mkdir()
    (d / "share" / "licvdb" / "__pycache__" / "x.pyc").write_bytes(b"")
    return d


def test_engine_zip_carries_the_bundle_for_linux(tmp_path):
    version = ".".join(map(str, licvdb.bl_info["version"]))
    bundle = make_bundle(tmp_path / "bundle", version)
    out = tmp_path / "zips"
    proc = subprocess.run([os.path.join(ROOT, "scripts", "package-addon"), "--engine", str(bundle), str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(out)) == [f"licvdb-{version}-blender-linux-x64.zip", "licvdb-blender-addon.zip",
                                       "licvdb-blender-extension.zip"]
    with zipfile.ZipFile(out / f"licvdb-{version}-blender-linux-x64.zip") as z:
        names = z.namelist()
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode("utf-8"))
        modes = {n: (z.getinfo(n).external_attr >> 16) & 0o777 for n in names}
    assert sorted(n for n in names if not n.startswith("engine/")) == package_files()
    assert sorted(n for n in names if n.startswith("engine/")) == sorted(
        "engine/" + rel for rel in [*BUNDLE, "VERSION"])
    assert manifest["platforms"] == ["linux-x64"]
    assert manifest_errors(manifest) == []
    with open(os.path.join(PKG, "blender_manifest.toml"), "rb") as f:
        source = tomllib.load(f)
    assert {k: v for k, v in manifest.items() if k != "platforms"} == source
    assert modes["engine/bin/licvdb"] == 0o755  # kept in the zip (Blender's installer drops them)
    # The platform-neutral extension zip is unchanged: no engine, no platforms.
    with zipfile.ZipFile(out / "licvdb-blender-extension.zip") as z:
        assert sorted(z.namelist()) == package_files()
        assert "platforms" not in tomllib.loads(z.read("blender_manifest.toml").decode("utf-8"))


def test_engine_that_is_not_a_bundle_is_refused(tmp_path):
    bundle = make_bundle(tmp_path / "bundle", "0.1.0")
    (bundle / "libexec" / "licvdb" / "licvdb").unlink()
    script = os.path.join(ROOT, "scripts", "package-addon")
    proc = subprocess.run([script, "--engine", str(bundle), str(tmp_path / "zips")], capture_output=True, text=True)
    assert proc.returncode == 2 and "libexec/licvdb/licvdb" in proc.stderr, proc.stderr
    assert not os.path.exists(tmp_path / "zips") or not os.listdir(tmp_path / "zips"), "nothing written"
    proc = subprocess.run([script, "--engine", str(tmp_path / "none"), str(tmp_path / "zips")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "is not a folder" in proc.stderr, proc.stderr
    (bundle / "EXECUTABLES").unlink()
    proc = subprocess.run([script, "--engine", str(bundle), str(tmp_path / "zips")], capture_output=True, text=True)
    assert proc.returncode == 2 and "no EXECUTABLES" in proc.stderr, proc.stderr


def test_package_imports_are_relative():
    """An extension is imported as bl_ext.<repository>.licvdb: the package must not import itself
    by the name ``licvdb`` nor look its preferences up by that name."""
    for name in package_files():
        if not name.endswith(".py"):
            continue
        with open(os.path.join(PKG, name), encoding="utf-8") as f:
            src = f.read()
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, ast.ImportFrom):
                assert node.level > 0 or (node.module or "").split(".")[0] != "licvdb", f"{name}: {ast.dump(node)}"
            elif isinstance(node, ast.Import):
                assert all(a.name.split(".")[0] != "licvdb" for a in node.names), f"{name}: {ast.dump(node)}"
        assert not re.search(r"addons(\.get\(|\[)\s*[\"']licvdb[\"']", src), f"{name} names its own module"


def run_blender(script, env_extra, tmp_path):
    """Run ``script`` in a separate Blender (background, factory settings) with user scripts and
    config in ``tmp_path``; returns its output. The add-on is *not* on sys.path there."""
    env = {k: v for k, v in os.environ.items() if k != "LICVDB_EXECUTABLE"}
    env.update(BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"), BLENDER_USER_CONFIG=str(tmp_path / "config"),
               **env_extra)
    path = tmp_path / "script.py"
    path.write_text(textwrap.dedent(script))
    proc = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup",
                           "--python-exit-code", "1", "-P", str(path)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def test_legacy_zip_installs_and_enables(zips, tmp_path):
    """Blender 3.x's way (docs/blender.md, "Install"): Preferences > Add-ons > Install… = addon_install."""
    out = run_blender(f"""
        import os, addon_utils, bpy
        assert bpy.ops.preferences.addon_install(filepath={str(zips['legacy'])!r}) == {{'FINISHED'}}
        addon_utils.enable("licvdb", default_set=True, handle_error=None)
        import licvdb
        assert licvdb.__file__.startswith({str(tmp_path / 'scripts')!r}), licvdb.__file__
        assert "licvdb" in bpy.context.preferences.addons
        assert hasattr(bpy.ops.licvdb, "import_bake") and hasattr(bpy.types.Object, "licvdb")
        print("LEGACY-OK", licvdb.__file__)
    """, {}, tmp_path)
    assert "LEGACY-OK" in out

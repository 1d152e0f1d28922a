"""Reading a bake's sidecar manifest (OUT.licvdb.json) and finding the files of a bake.

Pure Python (no ``bpy``), so it is usable and testable outside Blender. Blender's Python API
cannot read VDB metadata, so everything the add-on needs about a bake comes from the manifest
that ``licvdb bake`` writes next to its output:

``{"licvdb_version", "recipe", "frames", "cyclic", "files": [...], "voxel_size",
"colormap": {"scalar", "name", "range", "space", "points": [[pos, r, g, b], ...]} | null,
"range", "grids": [{"name", "type", "active_voxels", "voxel_size", "world_bbox"}]}``
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field

#: ``OUT_0001.vdb``: licvdb numbers the frames of a loop from 1 with four digits.
_FRAME_RE = re.compile(r"^(?P<stem>.*?)_?(?P<num>\d+)\.vdb$", re.IGNORECASE)


#: ``OUT.vdb`` → ``OUT.licvdb.json`` (licvdb's manifestPath). Older bakes wrote
#: ``OUT.json``: still read, after the new name.
MANIFEST_SUFFIX = ".licvdb.json"
LEGACY_MANIFEST_SUFFIX = ".json"


def manifest_path(vdb_path: str) -> str:
    """The manifest licvdb writes for a bake to ``vdb_path`` (one for a whole loop)."""
    root, ext = os.path.splitext(vdb_path)
    return (root if ext.lower() == ".vdb" else vdb_path) + MANIFEST_SUFFIX


def bake_name(manifest_file: str) -> str:
    """The bake's name from its manifest: ``loop.licvdb.json`` (or an old ``loop.json``) → ``loop``."""
    base = os.path.basename(manifest_file)
    for suffix in (MANIFEST_SUFFIX, LEGACY_MANIFEST_SUFFIX):
        if base.endswith(suffix):
            return base[:-len(suffix)]
    return os.path.splitext(base)[0]


class ManifestError(Exception):
    """A manifest that is missing, unreadable or not in licvdb's format."""


@dataclass
class GridInfo:
    name: str
    type: str = ""
    active_voxels: int = 0
    voxel_size: tuple = (0.0, 0.0, 0.0)
    world_bbox: tuple = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # (min xyz, max xyz), world units


@dataclass
class Colormap:
    scalar: str
    name: str
    range: tuple  # (lo, hi) in the scalar's units
    points: list  # [(pos, r, g, b)], positions in [0, 1], colours in ``space``
    space: str = "sRGB"


@dataclass
class Manifest:
    """What the add-on needs to know about one bake (a still or a whole loop)."""

    path: str  # the manifest file
    files: list  # absolute paths of the .vdb files, in frame order
    frames: int = 1
    cyclic: bool = False
    voxel_size: float = 0.0
    grids: list = field(default_factory=list)  # [GridInfo]
    colormap: Colormap | None = None
    recipe: dict = field(default_factory=dict)
    version: str = ""
    unsteady: bool = False  # frames of an unsteady field sequence, numbered as its frames
    first_frame: int = 1  # unsteady: the field's first frame number (plays from that scene frame)

    def grid(self, name: str) -> GridInfo | None:
        return next((g for g in self.grids if g.name == name), None)

    @property
    def grid_names(self) -> list:
        return [g.name for g in self.grids]

    @property
    def world_bbox(self) -> tuple:
        """Union of the grids' world bounding boxes: ((min x, y, z), (max x, y, z))."""
        if not self.grids:
            return ((0.0,) * 3, (0.0,) * 3)
        lo = tuple(min(g.world_bbox[0][a] for g in self.grids) for a in range(3))
        hi = tuple(max(g.world_bbox[1][a] for g in self.grids) for a in range(3))
        return (lo, hi)


def _vec3(value, what: str) -> tuple:
    if not (isinstance(value, (list, tuple)) and len(value) == 3):
        raise ManifestError(f"{what}: expected a list of 3 numbers, got {value!r}")
    return tuple(float(v) for v in value)


def parse_manifest(data: dict, path: str) -> Manifest:
    """A Manifest from the decoded JSON of ``path`` (used to resolve relative file names)."""
    if not isinstance(data, dict) or "files" not in data or "grids" not in data:
        raise ManifestError(f"{path}: not a licvdb manifest (expected keys \"files\" and \"grids\")")
    base = os.path.dirname(os.path.abspath(path))
    files = [os.path.join(base, f) for f in data["files"]]
    if not files:
        raise ManifestError(f"{path}: \"files\" is empty")
    grids = []
    for g in data["grids"]:
        bbox = g.get("world_bbox") or [[0, 0, 0], [0, 0, 0]]
        grids.append(GridInfo(name=str(g["name"]), type=str(g.get("type", "")),
                              active_voxels=int(g.get("active_voxels", 0)),
                              voxel_size=_vec3(g.get("voxel_size", [0, 0, 0]), f"{path}: grid voxel_size"),
                              world_bbox=(_vec3(bbox[0], f"{path}: world_bbox"),
                                          _vec3(bbox[1], f"{path}: world_bbox"))))
    cmap = None
    c = data.get("colormap")
    if c:
        cmap = Colormap(scalar=str(c.get("scalar", "")), name=str(c.get("name", "")),
                        range=tuple(float(v) for v in c.get("range", (0.0, 1.0))),
                        points=[tuple(float(v) for v in p) for p in c.get("points", [])],
                        space=str(c.get("space", "sRGB")))
    voxel = data.get("voxel_size")
    if voxel is None and grids:
        voxel = grids[0].voxel_size[0]
    return Manifest(path=os.path.abspath(path), files=files, frames=int(data.get("frames", len(files))),
                    cyclic=bool(data.get("cyclic", False)), voxel_size=float(voxel or 0.0), grids=grids,
                    colormap=cmap, recipe=data.get("recipe") or {}, version=str(data.get("licvdb_version", "")),
                    unsteady=bool(data.get("unsteady", False)), first_frame=int(data.get("first_frame", 1)))


def read_manifest(path: str) -> Manifest:
    """Read and parse a manifest file. Raises ManifestError naming the file and the problem."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise ManifestError(f"manifest {path} does not exist") from None
    except (OSError, ValueError) as e:
        raise ManifestError(f"manifest {path} cannot be read: {e}") from None
    return parse_manifest(data, path)


def frame_number(path: str) -> int | None:
    """The frame number at the end of a file name (``OUT_0003.vdb`` → 3), or None."""
    m = _FRAME_RE.match(os.path.basename(path))
    return int(m.group("num")) if m else None


def manifest_candidates(vdb_path: str) -> list:
    """Where the manifest of ``vdb_path`` may be: ``OUT.licvdb.json`` beside ``OUT.vdb``; for a
    frame ``OUT_0003.vdb`` of a loop first ``OUT_0003.licvdb.json`` (a still whose name ends in
    digits, or one frame of a per-frame bake), then ``OUT.licvdb.json`` (the loop's manifest).
    Each is followed by its older name ``….json`` (bakes made before the rename)."""
    root, _ = os.path.splitext(vdb_path)
    roots = [root]
    m = re.match(r"^(.*?)_?\d+$", root)
    if m and m.group(1):
        roots.append(m.group(1))
    return [r + suffix for r in roots for suffix in (MANIFEST_SUFFIX, LEGACY_MANIFEST_SUFFIX)]


def find_manifest(vdb_path: str) -> Manifest | None:
    """The manifest that lists ``vdb_path`` (None if there is none: a VDB not made by licvdb)."""
    target = os.path.abspath(vdb_path)
    for candidate in manifest_candidates(vdb_path):
        if os.path.isfile(candidate):
            try:
                man = read_manifest(candidate)
            except ManifestError:
                if candidate.endswith(MANIFEST_SUFFIX):
                    raise
                continue  # OUT.json beside OUT.vdb may be a recipe, not an old manifest
            if any(os.path.abspath(f) == target for f in man.files):
                return man
    return None


def sequence_files(vdb_path: str) -> list:
    """All files of the numbered sequence ``vdb_path`` belongs to (same stem, same digit count,
    consecutive numbers from the lowest one present), sorted; ``[vdb_path]`` if it is not
    numbered."""
    name = os.path.basename(vdb_path)
    m = re.match(r"^(?P<pre>.*?)(?P<num>\d+)(?P<ext>\.vdb)$", name, re.IGNORECASE)
    if not m:
        return [vdb_path]
    directory = os.path.dirname(vdb_path) or "."
    pre, width, ext = m.group("pre"), len(m.group("num")), m.group("ext")
    pattern = re.compile(re.escape(pre) + r"(\d{%d})" % width + re.escape(ext) + "$")
    numbers = sorted(int(mm.group(1)) for f in os.listdir(directory) if (mm := pattern.match(f)))
    if not numbers:
        return [vdb_path]
    # Keep the consecutive run that contains the chosen file.
    mine = int(m.group("num"))
    run = [mine]
    n = mine - 1
    while n in numbers:
        run.insert(0, n)
        n -= 1
    n = mine + 1
    while n in numbers:
        run.append(n)
        n += 1
    return [os.path.join(directory, f"{pre}{k:0{width}d}{ext}") for k in run]

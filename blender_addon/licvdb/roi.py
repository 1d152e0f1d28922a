"""A region of interest given as fractions of the field's top speed (``scene.licvdb_bake``'s
*Fraction of top speed*): presets then suit any field, whatever its units.

licvdb's ``roi.range`` is in the scalar's own units. make_recipe writes a relative range as
``{"fraction_of_top_speed": [lo, hi]}``; ``resolve`` turns it into speeds just before the bake
runs, from the top speed ``licvdb info --json`` reports for the field's velocity grid (its
``value_range`` is |v| for a vector grid; split ``vel.x/.y/.z`` grids give an upper bound).
"""

import json
import math
import re
import subprocess

from . import engine

RELATIVE = "fraction_of_top_speed"
VELOCITY_NAMES = ("velocity", "vel", "v")


class RoiError(Exception):
    """The top speed cannot be found; the message says why."""


def first_file(field: dict) -> str:
    """The field's first file: ``path`` itself, or a ``####`` pattern's first frame."""
    path, frames = field.get("path", ""), field.get("frames")
    m = re.search(r"#+", path)
    if not m or not frames:
        return path
    return path[:m.start()] + f"{frames[0]:0{len(m.group())}d}" + path[m.end():]


def top_speed(grids: list, name: str) -> float:
    """The largest |v| of grid ``name`` ("" = velocity, vel, v, else the only vec3 grid; NAME.x/.y/.z
    split grids bound it) among ``licvdb info --json``'s ``grids``. Raises RoiError."""
    by_name = {g.get("name"): g for g in grids}
    vectors = [g["name"] for g in grids if str(g.get("value_type", "")).startswith("vec3")]
    if name:
        names = [name]
    else:
        names = [n for n in VELOCITY_NAMES if n in vectors] or (vectors if len(vectors) == 1 else [])
        names += list(VELOCITY_NAMES)  # (split NAME.x/.y/.z grids)
    for n in names:
        g = by_name.get(n)
        if g is not None and "value_range" in g and n in vectors:
            return float(g["value_range"][1])
        parts = [by_name.get(f"{n}.{c}") for c in "xyz"]
        if all(p is not None and "value_range" in p for p in parts):
            return math.sqrt(sum(max(abs(float(v)) for v in p["value_range"]) ** 2 for p in parts))
    raise RoiError(f"no velocity grid {name or '(velocity, vel, v)'} with a value range among "
                   f"{', '.join(by_name) or 'no grids'}")


def field_top_speed(executable: str, field: dict) -> float:
    """The top speed of the recipe's ``field`` (licvdb info on its first file). Raises RoiError."""
    path = first_file(field)
    try:
        proc = subprocess.run([executable, "info", "--json", path], capture_output=True, text=True, timeout=120,
                              env=engine.engine_env())
    except (OSError, subprocess.TimeoutExpired) as e:
        raise RoiError(f"licvdb info {path} failed: {e}") from None
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        raise RoiError(f"licvdb info cannot read {path} ({last}); a range relative to the top speed needs a .vdb "
                       "field: turn off Fraction of top speed and give the range in the field's units")
    try:
        grids = json.loads(proc.stdout).get("grids", [])
    except ValueError:
        raise RoiError(f"licvdb info {path} printed no JSON") from None
    return top_speed(grids, field.get("grid", ""))


def resolve(executable: str, recipe: dict) -> bool:
    """Turn a relative ROI range of ``recipe`` into speeds (in place); returns whether there was
    one. Raises RoiError."""
    roi = recipe.get("roi") or {}
    rel = roi.get("range") if isinstance(roi.get("range"), dict) else None
    if rel is None:
        return False
    top = field_top_speed(executable, recipe.get("field", {}))
    lo, hi = rel[RELATIVE]
    roi["range"] = [lo * top, hi * top]
    return True

#!/usr/bin/env python3
"""Check the README's and docs/recipe.md's tables against licvdb's own tables.

`licvdb help --json` lists the engines, kernels, spot distributions, derived scalars, colormaps,
input formats and output grids from the tables the program uses. This script fails (exit 1,
naming each difference) when the docs leave one out or list one that does not exist:

* docs/recipe.md's "Output grids" table must be exactly the output-grid table (every column);
  `--fix` rewrites it from the program;
* docs/recipe.md's value column of `lic.engine`, `lic.kernel`, `input.distribution` and
  `field.format` must list exactly the program's choices, and `color.scalar` every derived scalar;
* the README's flag table must have a row for every `--write-*` flag with its recipe key, and its
  `--engine`, `--kernel`, `--distribution`, `--color` and `--colormap` rows must name every choice.

Usage: check_doc_tables.py --licvdb build/vdbexport/licvdb [--root .] [--fix]
"""

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

WHEN = {"always": "always", "spots": "spot bakes", "asked": "asked for", "color": "with `color`"}
GRIDS_HEADING = "## Output grids"
GRIDS_HEADER = ["grid", "type", "written", "recipe key, flag", "each active voxel holds", "metadata",
                "Blender add-on"]


def grid_rows(choices):
    """The output-grid table as docs/recipe.md shows it: one list of cells per grid."""
    rows = []
    for g in choices["grids"]:
        key = f"`{g['recipe_key']}`, `{g['flag']}`" if g["flag"] else ""
        rows.append([f"`{g['name']}`", g["type"], WHEN[g["when"]], key, g["fill"], g["metadata"], g["blender"]])
    return rows


def markdown_table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def cells(line):
    """The cells of a markdown table row (| a | b |), stripped; pipes escaped as \\| stay."""
    parts = re.split(r"(?<!\\)\|", line.strip())
    return [p.strip() for p in parts[1:-1]]


def table_after(text, heading):
    """(start, end, rows) of the first table after `heading` (character offsets of the table)."""
    at = text.find("\n" + heading + "\n")
    if at < 0:
        return None
    m = re.search(r"(?m)^\|.*\n(?:^\|.*(?:\n|$))+", text[at:])
    if not m:
        return None
    start, end = at + m.start(), at + m.end()
    lines = text[start:end].rstrip("\n").split("\n")
    return start, end, [cells(l) for l in lines[2:]]


def row_of(text, first_cell):
    """The cells of the table row whose first cell is `first_cell` (e.g. "`lic.kernel`")."""
    for line in text.splitlines():
        if line.startswith("|") and cells(line)[:1] == [first_cell]:
            return cells(line)
    return None


def ticked(cell):
    return re.findall(r"`([^`]+)`", cell)


def check(root, choices, fix):
    errors = []
    recipe_md = root / "docs" / "recipe.md"
    readme = root / "README.md"
    recipe = recipe_md.read_text(encoding="utf-8")
    readme_text = readme.read_text(encoding="utf-8")

    # docs/recipe.md: the output grids, exactly.
    want = grid_rows(choices)
    found = table_after(recipe, GRIDS_HEADING)
    if fix:
        table = markdown_table(GRIDS_HEADER, want) + "\n"
        if found:
            recipe = recipe[:found[0]] + table + recipe[found[1]:]
        else:
            recipe = recipe.rstrip("\n") + "\n\n" + GRIDS_HEADING + "\n\n" + table
        recipe_md.write_text(recipe, encoding="utf-8")
        found = table_after(recipe, GRIDS_HEADING)
    if not found:
        errors.append(f"docs/recipe.md: no table under \"{GRIDS_HEADING}\"")
    else:
        have = found[2]
        for i in range(max(len(want), len(have))):
            w = want[i] if i < len(want) else None
            h = have[i] if i < len(have) else None
            if w != h:
                errors.append(f"docs/recipe.md output grids, row {i + 1}: the program has {w}, the doc {h}")

    # docs/recipe.md: value columns that list every choice, and nothing else.
    exact = {"`lic.engine`": ["auto"] + choices["engines"], "`lic.kernel`": choices["kernels"],
             "`input.distribution`": choices["distributions"],
             "`field.format`": ["auto"] + [f["name"] for f in choices["formats"]]}
    for key, names in exact.items():
        row = row_of(recipe, key)
        if row is None:
            errors.append(f"docs/recipe.md: no row for {key}")
        elif sorted(ticked(row[1])) != sorted(names):
            errors.append(f"docs/recipe.md {key}: lists {ticked(row[1])}; the program has {names}")
    row = row_of(recipe, "`color.scalar`")
    missing = [s for s in choices["scalars"] if row is None or f"`{s}`" not in row[2]]
    if missing:
        errors.append(f"docs/recipe.md `color.scalar`: does not name {missing}")

    # README: a flag-table row for every --write-* flag, and every choice named in its row.
    flags = {}
    for g in choices["grids"]:
        if g["flag"]:
            flags[g["flag"]] = g["recipe_key"]
    for flag, key in flags.items():
        row = row_of(readme_text, f"`{flag}`")
        if row is None or row[1] != f"`{key}`":
            errors.append(f"README.md flag table: no row `{flag}` | `{key}`")
    named = {"`--engine`": choices["engines"], "`--kernel`": choices["kernels"],
             "`--distribution`": choices["distributions"], "`--color S`": choices["scalars"],
             "`--colormap M`": choices["colormaps"]}
    for flag, names in named.items():
        row = row_of(readme_text, flag)
        if row is None:
            errors.append(f"README.md flag table: no row {flag}")
            continue
        missing = [n for n in names if f"`{n}`" not in row[3]]
        if missing:
            errors.append(f"README.md {flag}: does not name {missing}")
    return errors


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--licvdb", required=True, help="the licvdb program")
    ap.add_argument("--root", default=str(Path(__file__).resolve().parent.parent), help="the source tree")
    ap.add_argument("--fix", action="store_true", help="rewrite docs/recipe.md's output-grid table")
    args = ap.parse_args()
    out = subprocess.run([args.licvdb, "help", "--json"], check=True, capture_output=True, text=True).stdout
    errors = check(Path(args.root), json.loads(out), args.fix)
    for e in errors:
        print(e, file=sys.stderr)
    if errors:
        print(f"{len(errors)} difference(s) between the docs and `licvdb help --json`", file=sys.stderr)
        return 1
    print("docs tables match licvdb help --json")
    return 0


if __name__ == "__main__":
    sys.exit(main())

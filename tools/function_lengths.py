#!/usr/bin/env python3
"""List the longest functions of the product's C++ code (lambdas count toward the function that
holds them) and fail when one is longer than the limit.

Usage: tools/function_lengths.py [--limit N] [--top K] [PATH ...]   (default: lic vdbexport)
Needs Universal Ctags (Debian package universal-ctags). Exit 1 when a function is over the limit.
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def functions(paths):
    cmd = ["ctags", "-R", "--languages=C++", "--kinds-C++=f", "--fields=+ne", "--output-format=json", "-o", "-"]
    out = subprocess.run(cmd + [str(p) for p in paths], cwd=ROOT, check=True, capture_output=True, text=True).stdout
    for line in out.splitlines():
        tag = json.loads(line)
        if tag.get("_type") != "tag" or "end" not in tag:
            continue
        # A lambda or local function is part of the function around it.
        if tag.get("scopeKind") == "function":
            continue
        name = tag["name"]
        if tag.get("scope"):
            name = tag["scope"] + "::" + name
        yield tag["end"] - tag["line"] + 1, tag["path"], tag["line"], name


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, default=150, help="longest allowed function, lines [150]")
    ap.add_argument("--top", type=int, default=10, help="how many of the longest to list [10]")
    ap.add_argument("paths", nargs="*", default=["lic", "vdbexport"])
    args = ap.parse_args()
    found = sorted(functions(args.paths), reverse=True)
    for length, path, line, name in found[: args.top]:
        print(f"{length:5d}  {path}:{line}  {name}")
    over = [f for f in found if f[0] > args.limit]
    print(f"function_lengths: {len(found)} functions, {len(over)} longer than {args.limit} lines, "
          f"{sum(1 for f in found if f[0] > 100)} longer than 100, {sum(1 for f in found if f[0] > 60)} longer than 60")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())

"""Run the Blender tests inside Blender:

    blender -b --factory-startup --python-exit-code 1 -P tests/blender/run.py -- \
        --licvdb build/vdbexport/licvdb [pytest arguments…]

Puts blender_addon/ on sys.path, runs pytest on this directory and makes Blender exit non-zero
(through --python-exit-code) when a test fails.
"""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def main():
    sys.dont_write_bytecode = True  # no __pycache__ in the source tree
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    pytest_args = []
    i = 0
    while i < len(argv):
        if argv[i] == "--licvdb" and i + 1 < len(argv):
            os.environ["LICVDB_EXECUTABLE"] = os.path.abspath(argv[i + 1])
            i += 2
            continue
        pytest_args.append(argv[i])
        i += 1
    if not os.environ.get("LICVDB_EXECUTABLE"):
        raise SystemExit("run.py: pass --licvdb PATH (the licvdb executable the tests bake with)")
    sys.path.insert(0, os.path.join(ROOT, "blender_addon"))
    sys.path.insert(0, HERE)

    import pytest

    code = pytest.main([HERE, "-v", "-p", "no:cacheprovider", "-o", "console_output_style=classic",
                        *pytest_args])
    # Leave an empty scene: a fluid domain left by a failed test makes mantaflow abort at exit.
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    if code != 0:
        # An exception (not sys.exit) so that --python-exit-code 1 makes Blender exit 1.
        raise RuntimeError(f"Blender tests failed (pytest exit code {int(code)})")


main()

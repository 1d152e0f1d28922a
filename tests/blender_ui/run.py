"""Run the add-on tests that need Blender's window and event loop (operator ``invoke`` as the
menu starts it), in a real Blender window on a virtual X server:

    xvfb-run -a blender --factory-startup -P tests/blender_ui/run.py -- \
        --licvdb build/vdbexport/licvdb [pytest arguments…]

Background mode (``blender -b``, tests/blender) has no window event, so ``bpy.ops.X('INVOKE_DEFAULT')``
runs ``execute`` there and never ``invoke``; and only a call that is not nested in a Python
operator call (``undo=True``) gets the operator's last-used properties restored, as a menu
click does. Here pytest runs from a timer once the event loop is up, with the 3D view as
context, and Blender exits with pytest's exit code (os._exit: a timer cannot make Blender exit
non-zero otherwise).
"""

import os
import sys
import traceback

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def _args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    pytest_args, i = [], 0
    while i < len(argv):
        if argv[i] == "--licvdb" and i + 1 < len(argv):
            os.environ["LICVDB_EXECUTABLE"] = os.path.abspath(argv[i + 1])
            i += 2
            continue
        pytest_args.append(argv[i])
        i += 1
    return pytest_args


def _run(pytest_args):
    code = 1
    try:
        if bpy.app.background:
            raise SystemExit("tests/blender_ui/run.py needs a window: run Blender without -b (under xvfb-run)")
        if not os.environ.get("LICVDB_EXECUTABLE"):
            raise SystemExit("run.py: pass --licvdb PATH (the licvdb executable the tests bake with)")
        import pytest

        code = int(pytest.main([HERE, "-v", "-p", "no:cacheprovider", "-o", "console_output_style=classic",
                                *pytest_args]))
    except SystemExit as e:
        print(e, file=sys.stderr)
    except BaseException:
        traceback.print_exc()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def main():
    sys.dont_write_bytecode = True  # no __pycache__ in the source tree
    pytest_args = _args()
    sys.path.insert(0, os.path.join(ROOT, "blender_addon"))
    sys.path.insert(0, HERE)
    if bpy.app.background:  # no event loop: timers would never run
        _run(pytest_args)
    bpy.app.timers.register(lambda: _run(pytest_args), first_interval=0.5)


main()

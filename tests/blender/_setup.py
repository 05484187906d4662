"""Shared set-up for the add-on tests run inside Blender:
    blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_addon_X.py
with PYTHONPATH=<build>/python. Puts the repo root on sys.path, imports the add-on (repo
folder `addon/`) as the package `addon` and registers it. DEFORMKIT_MOCK=1 uses the stand-in
module in tests/blender/mock (plumbing only).

DEFORMKIT_FROM_ZIP=<legacy zip> instead installs that zip with Preferences > Add-ons > Install
(bpy.ops.preferences.addon_install) into BLENDER_USER_SCRIPTS, which must be a fresh directory,
and enables it with addon_utils, so the tests run the packaged add-on and its bundled native
module (run without build/python on PYTHONPATH; tests/blender/run_all.sh does this). The
installed package is then also importable as `addon`, and the repo root is not on sys.path."""
import importlib.util
import os
import sys
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
OUTPUT = os.path.join(HERE, "output")
os.makedirs(OUTPUT, exist_ok=True)
FROM_ZIP = os.environ.get("DEFORMKIT_FROM_ZIP", "")
ADDON_NAME = "deformkit"  # the legacy zip's top folder = the manifest id
if os.environ.get("DEFORMKIT_MOCK") == "1":
    sys.path.insert(0, os.path.join(HERE, "mock"))
if ROOT not in sys.path and not FROM_ZIP:
    sys.path.insert(0, ROOT)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import bpy  # noqa: E402
import numpy as np  # noqa: E402


def _script_name():
    argv = sys.argv
    i = argv.index("--python") + 1 if "--python" in argv else -1
    return os.path.splitext(os.path.basename(argv[i]))[0] if 0 < i < len(argv) else "test"


def _setup_failed(msg):
    print("FAIL set-up: %s" % msg)
    print("%s: 0 passed, 1 failed" % _script_name())
    sys.stdout.flush()
    raise SystemExit(1)


def _enable_installed():
    """addon_utils.enable with import/register errors reported, not swallowed."""
    import addon_utils
    errors = []
    mod = addon_utils.enable(ADDON_NAME, default_set=True,
                             handle_error=lambda ex: errors.append(traceback.format_exc()))
    if mod is None or errors:
        _setup_failed("addon_utils.enable(%r) failed:\n%s" % (ADDON_NAME, "".join(errors)))
    return mod


def install_from_zip(path):
    """Installs and enables the zip in a clean user directory; returns the add-on package."""
    user = os.environ.get("BLENDER_USER_SCRIPTS", "")
    if not user:
        _setup_failed("DEFORMKIT_FROM_ZIP needs BLENDER_USER_SCRIPTS set to a fresh directory")
    if not os.path.isfile(path):
        _setup_failed("no zip at %s (scripts/package.sh writes it)" % path)
    addons_dir = bpy.utils.user_resource("SCRIPTS", path="addons")
    if not os.path.realpath(addons_dir).startswith(os.path.realpath(user) + os.sep):
        _setup_failed("Blender's user add-on folder %s is not inside BLENDER_USER_SCRIPTS=%s"
                      % (addons_dir, user))
    if os.path.exists(os.path.join(addons_dir, ADDON_NAME)):
        _setup_failed("%s already has %s: not a clean user directory" % (addons_dir, ADDON_NAME))
    spec = importlib.util.find_spec(ADDON_NAME)
    if spec is not None:
        _setup_failed("a %r module is importable before the install (%s): run without "
                      "build/python on PYTHONPATH" % (ADDON_NAME, spec.origin))
    try:
        bpy.ops.preferences.addon_install(filepath=path)
    except RuntimeError as ex:
        _setup_failed("addon_install(%s): %s" % (path, ex))
    mod = _enable_installed()
    where = os.path.realpath(os.path.join(addons_dir, ADDON_NAME)) + os.sep
    if not os.path.realpath(mod.__file__).startswith(where):
        _setup_failed("enabled %s, not the installed copy in %s" % (mod.__file__, where))
    sys.modules["addon"] = mod  # tests say `from addon import X`: the installed package
    return mod


if FROM_ZIP:
    addon = install_from_zip(os.path.abspath(FROM_ZIP))
else:
    import addon  # noqa: E402
    addon.register()
from addon import solver, geonodes, native, handlers, methods  # noqa: E402,F401

dk = native.load()


class Results:
    def __init__(self, name):
        self.name, self.passed, self.failed = name, 0, 0

    def check(self, what, cond, detail=""):
        if cond:
            self.passed += 1
            print("PASS %s" % what)
        else:
            self.failed += 1
            print("FAIL %s %s" % (what, detail))
        return cond

    def run(self, fn):
        """Runs one test function; an exception is one failure (with its traceback)."""
        try:
            fn()
        except Exception:
            self.failed += 1
            print("FAIL %s raised:" % fn.__name__)
            traceback.print_exc()

    def finish(self):
        print("%s: %d passed, %d failed" % (self.name, self.passed, self.failed))
        sys.stdout.flush()
        if self.failed or self.passed == 0:
            sys.exit(1)


def reset_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if FROM_ZIP:
        # factory settings disable every add-on the factory preferences do not list
        if _enable_installed() is not addon:
            _setup_failed("re-enabling after read_factory_settings reloaded the add-on")
    solver.clear_cache()


def make_grid(name="Grid", nx=12, ny=6, size=(2.0, 1.0), bumpy=True):
    """A bumpy nx x ny grid of quads in the XY plane, centred at the origin."""
    verts, faces = [], []
    for j in range(ny):
        for i in range(nx):
            x = (i / (nx - 1) - 0.5) * size[0]
            y = (j / (ny - 1) - 0.5) * size[1]
            z = 0.03 * np.sin(7 * x) * np.cos(5 * y) if bumpy else 0.0
            verts.append((x, y, float(z)))
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            faces.append((a, a + 1, a + nx + 1, a + nx))
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def group(obj, name, indices, weights=None):
    vg = obj.vertex_groups.get(name) or obj.vertex_groups.new(name=name)
    if weights is None:
        vg.add(list(map(int, indices)), 1.0, "REPLACE")
    else:
        for i, w in zip(indices, weights):
            vg.add([int(i)], float(w), "REPLACE")
    return vg


def empty(name, location=(0, 0, 0)):
    e = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(e)
    e.location = location
    return e


def evaluated_positions(obj):
    return solver.evaluated_positions(obj)


def rest_positions(obj):
    return solver.rest_positions(obj.data)


def grid_setup(method="ARAP", nx=12, ny=6, handle_at=None):
    """Grid with the left two columns fixed and the right two columns a handle on an empty."""
    obj = make_grid(nx=nx, ny=ny)
    fixed = [j * nx + i for j in range(ny) for i in range(2)]
    handle = [j * nx + i for j in range(ny) for i in range(nx - 2, nx)]
    group(obj, "fixed", fixed)
    group(obj, "tip", handle)
    e = empty("Tip", handle_at or (1.0, 0.0, 0.0))
    bpy.ops.deformkit.add_deformer(method=method)
    d = obj.deformkit.deformers[0]
    d.fixed_group = "fixed"
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    return obj, d, e, np.array(fixed), np.array(handle)


def run_in_ui(fn, results, delay=1.0):
    """For tests that need a window (undo, modal operators, screenshots): run under
    `xvfb-run -a blender --factory-startup [--enable-event-simulate] --python FILE`.
    Calls fn() from a timer with a window/area context; if fn is a generator, each value it
    yields is a delay in seconds before it is resumed (so modal operators can run in between).
    Quits with the results' exit code."""
    import types
    state = {"gen": None}

    def _quit():
        print("%s: %d passed, %d failed" % (results.name, results.passed, results.failed))
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1 if (results.failed or results.passed == 0) else 0)

    def _tick():
        try:
            ctx = ui_context()
            with bpy.context.temp_override(**ctx):
                if state["gen"] is None:
                    r = fn()
                    if not isinstance(r, types.GeneratorType):
                        _quit()
                    state["gen"] = r
                try:
                    return float(next(state["gen"]))
                except StopIteration:
                    _quit()
        except Exception:
            results.failed += 1
            traceback.print_exc()
            _quit()
    bpy.app.timers.register(_tick, first_interval=delay, persistent=True)


def ui_context():
    """(window, largest area) for temp_override inside run_in_ui callbacks after a file load."""
    win = bpy.context.window_manager.windows[0]
    area = max(win.screen.areas, key=lambda a: a.width * a.height)
    return dict(window=win, area=area, screen=win.screen)

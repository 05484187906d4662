"""Shared set-up for the add-on tests run inside Blender:
    blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_addon_X.py
with PYTHONPATH=<build>/python. Puts the repo root on sys.path, imports the add-on (repo
folder `addon/`) as the package `addon` and registers it. DEFORMKIT_MOCK=1 uses the stand-in
module in tests/blender/mock (plumbing only)."""
import os
import sys
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
OUTPUT = os.path.join(HERE, "output")
os.makedirs(OUTPUT, exist_ok=True)
if os.environ.get("DEFORMKIT_MOCK") == "1":
    sys.path.insert(0, os.path.join(HERE, "mock"))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

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
    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64)


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

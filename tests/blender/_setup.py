"""Shared set-up for the add-on tests run inside Blender, either the blender program:
    blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_addon_X.py
or Blender as a Python module (a bpy wheel's virtual environment, scripts/venvs.sh):
    build/venvs/bpy-5.3/bin/python tests/blender/test_addon_X.py
with PYTHONPATH=<build>/python. Puts the repo root on sys.path, imports the add-on (repo
folder `addon/`) as the package `addon` and registers it. DEFORMKIT_MOCK=1 uses the stand-in
module in tests/blender/mock (plumbing only).

DEFORMKIT_FROM_ZIP=<zip> instead installs a packaged zip into a fresh user directory and
enables it, so the tests run the packaged add-on and its native module (run without
build/python on PYTHONPATH; tests/blender/run_all.sh does this):
- an extension zip (Blender 4.2+) with Get Extensions > Install from Disk
  (bpy.ops.extensions.package_install_files) into BLENDER_USER_RESOURCES; Blender installs the
  wheel its manifest lists, and the add-on is bl_ext.user_default.deformkit_addon;
- a legacy zip (Blender 3.4 to 4.1) with Preferences > Add-ons > Install
  (bpy.ops.preferences.addon_install) into BLENDER_USER_SCRIPTS.
The installed package is then also importable as `addon`, and the repo root is not on
sys.path."""
import importlib.util
import os
import sys
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
OUTPUT = os.path.join(HERE, "output")
os.makedirs(OUTPUT, exist_ok=True)
FROM_ZIP = os.environ.get("DEFORMKIT_FROM_ZIP", "")
PACKAGE = "deformkit_addon"  # the add-on's package: the legacy zip's top folder, the manifest id
ADDON_NAME = PACKAGE         # the module Blender enables: bl_ext.user_default.<id> for extensions
if os.environ.get("DEFORMKIT_MOCK") == "1":
    sys.path.insert(0, os.path.join(HERE, "mock"))
if ROOT not in sys.path and not FROM_ZIP:
    sys.path.insert(0, ROOT)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import bpy  # noqa: E402
import mathutils  # noqa: E402
import numpy as np  # noqa: E402

# the test shapes the Python suites use (tests/python/shapes.py, plain numpy), by its path:
# that folder's test modules stay off sys.path
_spec = importlib.util.spec_from_file_location(
    "dk_test_shapes", os.path.join(ROOT, "tests", "python", "shapes.py"))
shapes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(shapes)


# Blender as a Python module (the `bpy` wheels, run as `python FILE`) rather than the blender
# program: no --python argument, and no binary path.
AS_MODULE = not bpy.app.binary_path


def blender_command(blend=None, script=None, expr=None, args=()):
    """The command that runs `script` (or the Python source `expr`) in this same Blender, on
    `blend` if given, headless and with factory settings; `args` reach the script after "--".
    Under the blender program: blender -b --factory-startup [BLEND] --python... Under the bpy
    module: this Python, opening BLEND first, then running the script or source as __main__
    and ending through os._exit (see exit_now)."""
    if not AS_MODULE:
        cmd = [bpy.app.binary_path, "-b", "--factory-startup"] + ([blend] if blend else [])
        cmd += ["--python-exit-code", "1"]
        cmd += ["--python", script] if script else ["--python-expr", expr]
        return cmd + ["--"] + list(args)
    boot = ("import bpy, os, sys, traceback\n"
            "blend, script, expr = sys.argv[1], sys.argv[2], sys.argv[3]\n"
            "sys.argv = [script or '-c', '--'] + sys.argv[4:]\n"
            "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
            "if blend:\n"
            "    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)\n"
            "code = 0\n"
            "try:\n"
            "    src = open(script).read() if script else expr\n"
            "    exec(compile(src, script or '<expr>', 'exec'),\n"
            "         {'__name__': '__main__', '__file__': script or '<expr>'})\n"
            "except SystemExit as e:\n"
            "    code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)\n"
            "except BaseException:\n"
            "    traceback.print_exc()\n"
            "    code = 1\n"
            "sys.stdout.flush(); sys.stderr.flush()\n"
            "os._exit(code)\n")
    return [sys.executable, "-c", boot, blend or "", script or "", expr or ""] + list(args)


def _script_name():
    argv = sys.argv
    i = argv.index("--python") + 1 if "--python" in argv else (0 if AS_MODULE else -1)
    return os.path.splitext(os.path.basename(argv[i]))[0] if 0 <= i < len(argv) else "test"


def exit_now(code):
    """Ends the test process with `code`. The bpy module (4.5, 5.0) can hang in its own exit
    handlers after a file was written (a destructor waits on a thread that is gone), so there
    the process ends at once, its output flushed; the blender program exits normally."""
    sys.stdout.flush()
    sys.stderr.flush()
    if AS_MODULE:
        os._exit(code)
    sys.exit(code)


def _setup_failed(msg):
    print("FAIL set-up: %s" % msg)
    print("%s: 0 passed, 1 failed" % _script_name())
    exit_now(1)


def _enable_installed():
    """addon_utils.enable with import/register errors reported, not swallowed."""
    import addon_utils
    errors = []
    mod = addon_utils.enable(ADDON_NAME, default_set=True,
                             handle_error=lambda ex: errors.append(traceback.format_exc()))
    if mod is None or errors:
        _setup_failed("addon_utils.enable(%r) failed:\n%s" % (ADDON_NAME, "".join(errors)))
    return mod


def zip_is_extension(path):
    """An extension zip has blender_manifest.toml at its root; a legacy zip has one folder."""
    import zipfile
    with zipfile.ZipFile(path) as z:
        return "blender_manifest.toml" in z.namelist()


def _native_importable_before_install():
    spec = importlib.util.find_spec("deformkit")
    if spec is not None:
        _setup_failed("a 'deformkit' module is importable before the install (%s): run "
                      "without build/python on PYTHONPATH" % spec.origin)


def _install_legacy(path):
    """Preferences > Add-ons > Install (Blender 3.4 to 4.1) into BLENDER_USER_SCRIPTS."""
    user = os.environ.get("BLENDER_USER_SCRIPTS", "")
    if not user:
        _setup_failed("a legacy zip needs BLENDER_USER_SCRIPTS set to a fresh directory")
    addons_dir = bpy.utils.user_resource("SCRIPTS", path="addons")
    if not os.path.realpath(addons_dir).startswith(os.path.realpath(user) + os.sep):
        _setup_failed("Blender's user add-on folder %s is not inside BLENDER_USER_SCRIPTS=%s"
                      % (addons_dir, user))
    where = os.path.join(addons_dir, PACKAGE)
    if os.path.exists(where):
        _setup_failed("%s already exists: not a clean user directory" % where)
    _native_importable_before_install()
    try:
        bpy.ops.preferences.addon_install(filepath=path)
    except RuntimeError as ex:
        _setup_failed("addon_install(%s): %s" % (path, ex))
    return PACKAGE, where


def _install_extension(path):
    """Get Extensions > Install from Disk (Blender 4.2+) into the user_default repository of
    BLENDER_USER_RESOURCES; Blender installs the wheel the manifest lists."""
    user = os.environ.get("BLENDER_USER_RESOURCES", "")
    if not user:
        _setup_failed("an extension zip needs BLENDER_USER_RESOURCES set to a fresh directory")
    ext_dir = bpy.utils.user_resource("EXTENSIONS")
    if not os.path.realpath(ext_dir).startswith(os.path.realpath(user) + os.sep):
        _setup_failed("Blender's extensions folder %s is not inside BLENDER_USER_RESOURCES=%s"
                      % (ext_dir, user))
    where = os.path.join(ext_dir, "user_default", PACKAGE)
    if os.path.exists(where):
        _setup_failed("%s already exists: not a clean user directory" % where)
    _native_importable_before_install()
    try:
        bpy.ops.extensions.package_install_files(filepath=path, repo="user_default",
                                                 enable_on_install=False)
    except (RuntimeError, AttributeError) as ex:
        _setup_failed("extensions.package_install_files(%s): %s" % (path, ex))
    return "bl_ext.user_default." + PACKAGE, where


def install_from_zip(path):
    """Installs and enables the zip (an extension in 4.2+, else the legacy add-on) in a clean
    user directory; returns the add-on package."""
    global ADDON_NAME
    if not os.path.isfile(path):
        _setup_failed("no zip at %s (scripts/package.sh writes it)" % path)
    if zip_is_extension(path):
        if bpy.app.version < (4, 2, 0):
            _setup_failed("Blender %s cannot install an extension zip (4.2+)"
                          % bpy.app.version_string)
        ADDON_NAME, where = _install_extension(path)
    else:
        ADDON_NAME, where = _install_legacy(path)
    mod = _enable_installed()
    where = os.path.realpath(where) + os.sep
    if not os.path.realpath(mod.__file__).startswith(where):
        _setup_failed("enabled %s, not the installed copy in %s" % (mod.__file__, where))
    sys.modules["addon"] = mod  # tests say `from addon import X`: the installed package
    return mod


if FROM_ZIP:
    addon = install_from_zip(os.path.abspath(FROM_ZIP))
else:
    import addon  # noqa: E402
    addon.register()
from addon import (solver, geonodes, native, handlers, handles, methods, overlay, compat,  # noqa: E402,F401
                   properties, bake, pc2)

dk = native.load()


def handle_methods():
    """The registry's methods driven by handles (vertex groups moved by targets), which the
    handle set-ups test; the ones driven by a control object (a lattice, a cage) have
    test_addon_controls.py."""
    return [m for m in methods.METHODS if "vertex_groups" in native.control_kinds(m.native_class)]


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
        """Runs one test function; an exception is one failure (with its traceback). Prints
        its wall time (the suites' logs say where CI's minutes go). DEFORMKIT_ONLY=name,...
        runs only the functions named (while working on them)."""
        only = os.environ.get("DEFORMKIT_ONLY")
        if only and fn.__name__ not in only.split(","):
            return
        start = time.perf_counter()
        try:
            fn()
        except Exception:
            self.failed += 1
            print("FAIL %s raised:" % fn.__name__)
            traceback.print_exc()
        print("time %s: %.1f s" % (fn.__name__, time.perf_counter() - start))

    def finish(self):
        print("%s: %d passed, %d failed" % (self.name, self.passed, self.failed))
        exit_now(1 if (self.failed or self.passed == 0) else 0)


def reset_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if FROM_ZIP:
        # factory settings disable every add-on the factory preferences do not list
        if _enable_installed() is not addon:
            _setup_failed("re-enabling after read_factory_settings reloaded the add-on")
    solver.clear_cache()


def evaluated_frames_probe(seen, name="Grid"):
    """A frame_change_post handler that records `name`'s evaluated positions per frame in
    `seen` (what a render of that frame shows)."""
    def probe(scene, depsgraph):
        me = bpy.data.objects[name].evaluated_get(depsgraph).data
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        seen[scene.frame_current] = co.reshape(-1, 3)
    return probe


def rigged_arm(nodes, method="EMBEDDED", reset=True):
    """A 24 x 6 grid bent by a two-bone Armature modifier (first in the stack), the bones
    keyed over frames 1-20; a deformer of `method` after it (Embedded Deformation with
    `nodes`), fixed on the left end, with a handle on the right tip moved by a static edit
    after the bind at frame 1. `reset`: start from an empty scene (a window test resets it
    first, then builds the rig under a context made after the reset)."""
    if reset:
        reset_scene()
    nx, ny = 24, 6
    obj = make_grid(nx=nx, ny=ny)
    rest = rest_positions(obj)
    fixed = np.array([j * nx + i for j in range(ny) for i in range(2)])
    handle = np.array([j * nx + i for j in range(ny) for i in range(nx - 2, nx)])
    group(obj, "fixed", fixed)
    group(obj, "tip", handle)
    arm_rig(obj, {"upper": ((1, (0, 0, 0)), (10, (0, 0, 0.25)), (20, (0.2, 0, 0.1))),
                  "lower": ((1, (0, 0, 0)), (10, (0.5, 0, 0)), (20, (0.3, 0.2, -0.6)))})
    bpy.context.view_layer.objects.active = obj
    e = empty("Tip", (1.0, 0.0, 0.0))
    bpy.ops.deformkit.add_deformer(method=method)
    d = obj.deformkit.deformers[0]
    d.fixed_group = "fixed"
    if method == "EMBEDDED":
        d.options.nodes = nodes
        d.options.n_nodes = 40
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 20
    sc.frame_set(1)
    bpy.ops.deformkit.bind()
    bind_world = e.matrix_world.copy()
    e.location = (1.0, 0.1, 0.25)    # the edit, made on the pose of frame 1
    bpy.context.view_layer.update()
    return obj, d, e, fixed, handle, bind_world


def arm_rig(obj, keys):
    """A two-bone Armature modifier (two_bone_rig, first in obj's stack) bending obj (a mesh
    along x) at x = 0, the weights blended across -0.2..0.2, its bones' XYZ rotations keyed:
    keys = {bone: ((frame, (x, y, z)), ...)}. Returns the armature object."""
    rest = rest_positions(obj)
    w = np.clip((rest[:, 0] + 0.2) / 0.4, 0.0, 1.0)   # blend across the elbow at x = 0
    group(obj, "lower", range(len(rest)), w)
    group(obj, "upper", range(len(rest)), 1.0 - w)
    arm, ao = two_bone_rig("Rig")
    key_rotations(ao, keys)
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = ao
    return ao


def key_rotations(ao, keys):
    """Keys the XYZ rotations of armature object ao's pose bones: keys = {bone: ((frame,
    (x, y, z)), ...)}."""
    for name, frames in keys.items():
        pb = ao.pose.bones[name]
        pb.rotation_mode = "XYZ"
        for f, rot in frames:
            pb.rotation_euler = rot
            pb.keyframe_insert("rotation_euler", frame=f)


def bone_turn(obj, name):
    """The rotation (3 x 3, the mesh's space) by which the rig's bone `name` turns what it
    carries on the current frame."""
    rig = bpy.data.objects["Rig"]
    pb = rig.pose.bones[name]
    M = (obj.matrix_world.inverted() @ rig.matrix_world @ pb.matrix
         @ pb.bone.matrix_local.inverted() @ rig.matrix_world.inverted() @ obj.matrix_world)
    return np.array(M)[:3, :3]


def bake_differs_from(obj, d, shown, name):
    """Bakes d's frames min(shown) .. max(shown) to OUTPUT/name (a point cache) and returns the
    largest distance of a baked vertex from what played (`shown`: frame -> positions)."""
    first, last = min(shown), max(shown)
    path = os.path.join(OUTPUT, name)
    if os.path.exists(path):
        os.remove(path)
    bake.bake_pc2(bpy.context, obj, d, first, last, path)
    _, baked = pc2.read(path)
    return max(float(np.abs(np.array(baked[f - first]).reshape(-1, 3) - shown[f]).max())
               for f in shown)


def armature_input(obj, d):
    """What the Armature modifier gives the deformer: the stack with DeformKit's modifier off."""
    mod = geonodes.find_modifier(obj, d)
    mod.show_viewport = False
    handlers.enabled[0] = False
    try:
        return evaluated_positions(obj)
    finally:
        mod.show_viewport = True
        handlers.enabled[0] = True
        bpy.context.view_layer.update()


def tiny_workbench_render(sc, size, filepath):
    """A camera over the origin and a `size` x `size` Workbench render into `filepath`."""
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0, 0, 5)
    sc.render.engine = "BLENDER_WORKBENCH"
    sc.render.resolution_x = sc.render.resolution_y = size
    sc.render.filepath = filepath


def linked_object(name, data):
    """A new object of `data` linked to the scene, active and selected."""
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def armature_in_edit_mode(name="Rig"):
    """A new armature object linked to the scene, active and in Edit Mode, ready for its
    bones: (armature data, object). Leave Edit Mode with object.mode_set(mode="OBJECT")."""
    arm = bpy.data.armatures.new(name)
    ao = linked_object(name, arm)
    bpy.ops.object.mode_set(mode="EDIT")
    return arm, ao


def bend_end(angle, start=-0.5, length=1.0):
    """The rigid motion S.shapes.bend gives the part past the bend (x > start + length): the
    tube's middle on a circular arc of its own length, so the tube bends without stretching."""
    rho = length / angle
    return (mathutils.Matrix.Translation((start, rho, 0.0))
            @ mathutils.Matrix.Rotation(angle, 4, "Z")
            @ mathutils.Matrix.Translation((-(start + length), -rho, 0.0)))


def tube(n_len=25):
    """A closed tube along x from -1 to 1, radius 0.2 (tests/python/shapes.py)."""
    return shapes.capped_tube(n_len=n_len)


def tube_deformer(method, n_len=33, rig=None, **options):
    """A capped tube along x (tube), 'fixed' its x < -0.9 end, 'tip' its x > 0.9 end on an
    empty 'Tip' at (1, 0, 0), a deformer of `method` with that Fixed group, that handle and
    `options` (below the Armature `rig(obj)` makes, if any), in the current scene:
    (object, deformer, empty, fixed, tip)."""
    V, F = tube(n_len=n_len)
    obj = triangle_mesh_object(V, F, name="Tube")
    if rig is not None:
        rig(obj)
    fixed, tip = np.flatnonzero(V[:, 0] < -0.9), np.flatnonzero(V[:, 0] > 0.9)
    group(obj, "fixed", fixed)
    group(obj, "tip", tip)
    e = empty("Tip", (1.0, 0.0, 0.0))
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.deformkit.add_deformer(method=method)
    d = obj.deformkit.deformers[-1]
    d.fixed_group = "fixed"
    for name, value in options.items():
        setattr(d.options, name, value)
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    return obj, d, e, fixed, tip


def lower_bone_rig(obj):
    """A two-bone Armature first in obj's stack, its lower bone turned about z by 0 at frame
    1 and 0.8 at frame 5."""
    return arm_rig(obj, {"lower": ((1, (0, 0, 0.0)), (5, (0, 0, 0.8)))})


def check_edit_after_armature(R, obj, d, e, fixed, tip, tol, cache_name):
    """A deformer made by tube_deformer(..., rig=lower_bone_rig) in a 1-5 shot: bound at
    frame 1, its handle lifted by 0.2, frame 5 shown; checks that the Armature bends the
    input, that the fixed end stays where the Armature puts it, that the frame is the API's
    edit of the pose (the method's native class bound as the add-on binds, the handle where
    the lift, turned with the lower bone, puts it: test_addon_animation.py's rule), and that
    a bake writes what played (`cache_name` in OUTPUT). Returns (shown, input) at frame 5."""
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 5
    sc.frame_set(1)
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("binds after an Armature", d.bound and not d.status_is_error, d.status)
    e.location.z += 0.2
    sc.frame_set(5)
    got = evaluated_positions(obj)
    inp = armature_input(obj, d)
    rest = rest_positions(obj)
    R.check("the Armature bends the input", np.abs(inp - rest).max() > 0.3,
            np.abs(inp - rest).max())
    R.check("its fixed end stays where the Armature puts it",
            float(np.abs(got[fixed] - inp[fixed]).max()) < tol,
            float(np.abs(got[fixed] - inp[fixed]).max()))
    m = methods.get(d.method)
    mesh = dk.Mesh(rest, solver.triangles(obj.data))
    kw = dict(handles=[tip], fixed=fixed)
    native = getattr(dk, m.native_class)(mesh, **kw, **methods.bind_kwargs(m, d.options, rest,
                                                                           kw, mesh))
    T = np.array(e.matrix_world @ bind_world.inverted())
    edit = rest[tip] @ T[:3, :3].T + T[:3, 3] - rest[tip]
    B = bone_turn(obj, "lower")
    want = np.asarray(native.solve(inp[tip] + edit @ B.T, input_positions=inp,
                                   **methods.solve_kwargs(m, d.options, True)).positions)
    diff = float(np.abs(got - want).max())
    R.check("frame 5 is the API's edit of the pose (max %.2e)" % diff, diff < tol, diff)
    shown = {}
    for f in range(1, 6):
        sc.frame_set(f)
        shown[f] = evaluated_positions(obj)
    diff = bake_differs_from(obj, d, shown, cache_name)
    R.check("the bake = playback (max %.2e)" % diff, diff < tol, diff)
    return shown[5], inp


def bone_chain(joints, names, name="Rig"):
    """An armature of connected bones, bone k from joints[k] to joints[k + 1] named names[k]
    (each the child of the one before), back in Object Mode: (armature data, object)."""
    arm, ao = armature_in_edit_mode(name)
    prev = None
    for k, bone_name in enumerate(names):
        b = arm.edit_bones.new(bone_name)
        b.head, b.tail = tuple(joints[k]), tuple(joints[k + 1])
        if prev is not None:
            b.parent, b.use_connect = prev, True
        prev = b
    bpy.ops.object.mode_set(mode="OBJECT")
    return arm, ao


def two_bone_rig(name="Rig"):
    """Two connected bones along x, 'upper' from -1 to 0 and 'lower' from 0 to 1."""
    return bone_chain([(-1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)],
                      ["upper", "lower"], name)


def triangle_mesh_object(V, F, name="scan"):
    """A new object of the triangles F (m x 3) over the vertices V (n x 3), linked to the
    scene, active and selected (the benchmarks' scanned meshes)."""
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(V))
    me.vertices.foreach_set("co", V.astype(np.float32).ravel())
    me.loops.add(F.size)
    me.loops.foreach_set("vertex_index", F.astype(np.int32).ravel())
    me.polygons.add(len(F))
    me.polygons.foreach_set("loop_start", np.arange(0, F.size, 3, dtype=np.int32))
    if bpy.app.version < (4, 0):
        me.polygons.foreach_set("loop_total", np.full(len(F), 3, np.int32))
    me.update()
    return linked_object(name, me)


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
    return linked_object(name, me)


def group(obj, name, indices, weights=None):
    vg = obj.vertex_groups.get(name) or obj.vertex_groups.new(name=name)
    if weights is None:
        vg.add(list(map(int, indices)), 1.0, "REPLACE")
    else:
        for i, w in zip(indices, weights):
            vg.add([int(i)], float(w), "REPLACE")
    return vg


def add_loose_vertex(obj, co):
    """Adds a vertex on no face or edge (loose geometry, held at rest by every method) at the
    end of obj's mesh; returns its index."""
    import bmesh
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bm.verts.new(co)
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()
    return len(obj.data.vertices) - 1


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


def arap_reference(obj, d, handle, fixed, bind_T, T):
    """What one uninterrupted solve gives, through the Python API: an ARAP of the deformer's
    options on obj's rest mesh, solved cold at the bind pose `bind_T`, then warm for `T`
    (to the deformer's Max Iterations). Returns (the ARAP object, that SolveResult)."""
    mesh = dk.Mesh(solver.rest_positions(obj.data), solver.triangles(obj.data))
    o = d.options
    ref = dk.ARAP(mesh, [handle], fixed=fixed, weights=o.weights, energy=o.energy,
                  tolerance=o.tolerance, max_iterations=o.max_iterations,
                  acceleration=o.acceleration)
    ref.solve(transforms=bind_T, warm_start=False)
    return ref, ref.solve(transforms=T, warm_start=True)


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

"""Each method end to end on a small mesh: the add-on's evaluated result (GN modifier reading
the offset attribute written by the handler) equals the direct Python API result; weight maps
(ARAP stiffness from the material group, soft handle weights) reach the native call."""
import math
import sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Euler, Matrix  # noqa: E402

R = S.Results("test_addon_methods")
TOL = 2e-5  # float32 attribute storage


def direct(obj, d, kw_extra, T_list):
    """Same constraints through the Python API, solved in the same sequence (identity at bind,
    then each transform): returns the last positions."""
    m = S.methods.get(d.method)
    cls = getattr(S.dk, m.native_class)
    rest = S.solver.rest_positions(obj.data)
    tri = S.solver.triangles(obj.data)
    mesh = S.dk.Mesh(rest, tri)
    kw = dict(kw_extra)
    kw.update(S.methods.bind_kwargs(m, d.options, rest, kw_extra, mesh))
    meth = cls(mesh, **kw)
    skw = S.methods.solve_kwargs(m, d.options, cold=False)
    if S.solver.simulation.is_dynamic(m):
        # a simulation on a still scene shows its first frame: the reset to the handles'
        # placement (tests/blender/test_addon_simulation.py plays it)
        skw = dict(S.methods.solve_kwargs(m, d.options, cold=True), warm_start=False)
        skw.update(m.solve_args(obj, d.options, bpy.context.scene))
        T_list = T_list[-1:]
    out = None
    for T in [np.eye(4)[None]] + T_list:
        out = np.asarray(meth.solve(transforms=np.asarray(T), **skw).positions)
    return out


def one_method(mid):
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup(mid)
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("%s bind status" % mid, d.bound and not d.status_is_error, d.status)
    rest = S.rest_positions(obj)
    p0 = S.evaluated_positions(obj)
    R.check("%s at bind = rest" % mid, np.abs(p0 - rest).max() < TOL, np.abs(p0 - rest).max())
    Ts = []
    for loc, rot in (((1.0, 0.0, 0.4), (0, 0, 0)), ((1.1, 0.2, 0.3), (0.3, 0.0, 0.5))):
        e.location = loc
        e.rotation_euler = Euler(rot)
        bpy.context.view_layer.update()
        T = np.array(e.matrix_world @ bind_world.inverted())[None]
        Ts.append(T)
        got = S.evaluated_positions(obj)
        want = direct(obj, d, dict(handles=[handle], fixed=fixed), list(Ts))
        err = np.abs(got - want).max()
        moved = np.abs(want - rest).max()
        R.check("%s %s: add-on = API (max diff %.2e, moved %.2f)" % (mid, loc, err, moved),
                err < TOL and moved > 0.1, "diff %g moved %g" % (err, moved))
    hv = got[handle]
    want_h = (np.c_[rest[handle], np.ones(len(handle))] @ Ts[-1][0].T)[:, :3]
    # like a Hook: exactly, or for penalty handles (the native contract's flag) most of the way
    # (embedded deformation on this 72-vertex grid: 72 nodes, the request capped at the vertex
    # count, leave the handle 6% of its move behind; docs/methods/embedded.md)
    m = S.methods.get(mid)
    flags = S.dk._native._method_info(m.native_class)
    penalty, soft = flags["penalty_handles"], flags["soft_regions"]
    herr, hmove = np.abs(hv - want_h).max(), np.abs(want_h - rest[handle]).max()
    if soft:  # a least-squares fit (eigen deformation): most of the way, on average
        herr = np.abs(hv - want_h).max(axis=1).mean()
    R.check("%s handle vertices follow the target like a Hook" % mid,
            herr < (0.25 * hmove if soft else 0.08 * hmove if penalty else 1e-4), (herr, hmove))
    ferr = np.abs(got[fixed] - rest[fixed]).max(axis=1)
    R.check("%s fixed vertices stay" % mid,
            ferr.mean() < 0.25 * hmove if soft else ferr.max() < 1e-5, ferr.max())
    R.check("%s base mesh untouched" % mid, np.abs(S.rest_positions(obj) - rest).max() == 0)
    # Factor of the GN modifier scales the offset (keyframable modifier input)
    mod = S.geonodes.find_modifier(obj, d)
    S.geonodes.set_factor(mod, 0.5)
    half = S.evaluated_positions(obj)
    R.check("%s factor 0.5 halves the offset" % mid,
            np.abs(half - (rest + 0.5 * (got - rest))).max() < TOL)
    S.geonodes.set_factor(mod, 1.0)
    # object transform: moving the deformed object together with the target changes nothing
    e.parent = obj
    e.matrix_parent_inverse = obj.matrix_world.inverted()
    bpy.context.view_layer.update()
    before = S.evaluated_positions(obj)
    obj.location = (3.0, -1.0, 2.0)
    bpy.context.view_layer.update()
    after = S.evaluated_positions(obj)
    R.check("%s moving object and (child) target together keeps the shape" % mid,
            np.abs(after - before).max() < 1e-4, np.abs(after - before).max())
    return obj, d


def test_methods():
    for m in S.handle_methods():
        if not S.native.has_class(m.native_class):
            print("SKIP %s: deformkit.%s not in this build" % (m.id, m.native_class))
            continue
        one_method(m.id)


def test_bind_pose_of_transformed_object():
    """A rotated, scaled, moved object bound where it is: Blender's float32 matrix products
    put the bind-pose transform ~1e-8 off the identity; the solve must give the rest shape
    at once (ARAP used to run to its iteration cap on that rounding)."""
    for mid in ("ARAP", "LAPLACIAN"):
        S.reset_scene()
        obj, d, e, fixed, handle = S.grid_setup(mid)
        obj.location = (12.3, -4.5, 7.8)
        obj.rotation_euler = Euler((0.7, -0.4, 1.1))
        obj.scale = (1.3, 0.8, 1.1)
        e.location = (13.0, -4.0, 8.2)
        e.rotation_euler = Euler((0.2, 0.5, -0.3))
        bpy.context.view_layer.update()
        bpy.ops.deformkit.bind()
        rest = S.rest_positions(obj)
        p0 = S.evaluated_positions(obj)
        info = S.solver.runtime.get((obj.name, d.uid), {})
        R.check("%s transformed object at bind pose = rest" % mid,
                np.abs(p0 - rest).max() < 1e-6, np.abs(p0 - rest).max())
        if mid == "ARAP":  # (local-frame Laplacian editing always does its 2 solves)
            R.check("ARAP transformed object at bind pose: no iterations spent on rounding",
                    info.get("iterations", 99) <= 1, info)
        # a real (small) move is not snapped away
        e.location.z += 1e-3
        bpy.context.view_layer.update()
        p1 = S.evaluated_positions(obj)
        R.check("%s a 1e-3 move still moves the handle" % mid,
                np.abs(p1[handle] - rest[handle]).max() > 1e-4, np.abs(p1 - rest).max())


def test_registry_drives_ui():
    # every method has an options group with one property per registry option
    for m in S.methods.METHODS:
        S.reset_scene()
        obj = S.make_grid()
        bpy.ops.deformkit.add_deformer(method=m.id)
        d = obj.deformkit.deformers[-1]
        opts = getattr(d, S.methods.options_attr(m.id))
        R.check("%s options exist" % m.id, all(hasattr(opts, o.name) for o in m.options))
        mod = S.geonodes.find_modifier(obj, d)
        R.check("%s modifier named after the method" % m.id,
                mod is not None and m.label in mod.name, [x.name for x in obj.modifiers])


def test_stiffness_map():
    if not S.native.has_class("ARAP"):
        print("SKIP stiffness: no ARAP")
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    nx, ny = 12, 6
    mid = [j * nx + i for j in range(ny) for i in range(4, 8)]
    w = [0.25 + 0.75 * (i % 2) for i in range(len(mid))]
    S.group(obj, "stiff", mid, w)
    d.material_group = "stiff"
    d.options_arap.stiffness_scale = 20.0
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    e.location = (1.0, 0.0, 0.5)
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    s = np.ones(len(obj.data.vertices))
    s[mid] = 1.0 + 19.0 * np.array(w)
    T = np.array(e.matrix_world @ bind_world.inverted())[None]
    want = direct(obj, d, dict(handles=[handle], fixed=fixed, stiffness=s), [T])
    R.check("ARAP stiffness from weight paint = API", np.abs(got - want).max() < TOL,
            np.abs(got - want).max())


def test_soft_handles():
    m = S.methods.get("FALLOFF")
    if not S.native.has_class(m.native_class):
        print("SKIP soft handles: no Falloff")
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("FALLOFF")
    w = np.linspace(0.2, 1.0, len(handle))
    S.group(obj, "tip", handle, w)
    d.handles[0].use_weights = True
    bind_world = e.matrix_world.copy()
    try:
        bpy.ops.deformkit.bind()
    except RuntimeError as ex:
        R.check("Falloff soft handles bind", False, ex)
        return
    e.location = (1.0, 0.0, 0.5)
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    T = np.array(e.matrix_world @ bind_world.inverted())[None]
    want = direct(obj, d, dict(handles=[handle], fixed=fixed, handle_weights=[w]), [T])
    R.check("Falloff soft handle weights = API", np.abs(got - want).max() < TOL,
            np.abs(got - want).max())


def test_bone_target():
    if not S.native.has_class("ARAP"):
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    arm, ao = S.armature_in_edit_mode("Rig")
    b = arm.edit_bones.new("tipbone")
    b.head, b.tail = (1.0, 0, 0), (1.0, 0, 0.3)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.objects.active = obj
    h = d.handles[0]
    h.target = ao
    h.subtarget = "tipbone"
    bpy.ops.deformkit.bind()
    pb = ao.pose.bones["tipbone"]
    bind_world = ao.matrix_world @ pb.matrix
    pb.location = (0.0, 0.3, 0.0)   # bone-local y = along the bone = world +z
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    rest = S.rest_positions(obj)
    T = np.array(ao.matrix_world @ pb.matrix @ bind_world.inverted())
    want_h = (np.c_[rest[handle], np.ones(len(handle))] @ T.T)[:, :3]
    R.check("bone target moves the handle like a Hook", np.abs(got[handle] - want_h).max() < 1e-4,
            np.abs(got[handle] - want_h).max())
    R.check("bone moved up", abs((got[handle] - rest[handle])[:, 2].mean() - 0.3) < 1e-4)


def test_auto_rebind_on_group_change():
    if not S.native.has_class("ARAP"):
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    e.location = (1.0, 0.0, 0.4)
    bpy.context.view_layer.update()
    S.evaluated_positions(obj)  # the redraw that follows a drag in the UI
    # shrink the fixed group (membership change): re-bound automatically
    vg = obj.vertex_groups["fixed"]
    vg.remove([int(i) for i in fixed[1::2]])
    obj.data.update()
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    T = np.array(e.matrix_world @ bind_world.inverted())[None]
    want = direct(obj, d, dict(handles=[handle], fixed=fixed[0::2]), [T])
    R.check("group membership change re-binds automatically", np.abs(got - want).max() < 1e-3,
            np.abs(got - want).max())
    # switching the fixed group by name also re-binds
    S.group(obj, "fixed2", fixed)
    d.fixed_group = "fixed2"
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    want = direct(obj, d, dict(handles=[handle], fixed=fixed), [T])
    R.check("changing the fixed group re-binds", np.abs(got - want).max() < 1e-3,
            np.abs(got - want).max())


def test_skip_when_unchanged():
    if not S.native.has_class("ARAP"):
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    bpy.ops.deformkit.bind()
    e.location = (1.0, 0.0, 0.3)
    bpy.context.view_layer.update()
    calls = []
    orig = S.solver.cache._cache[(obj.name, d.uid)].native
    class Spy:
        def __getattr__(self, k):
            return getattr(orig, k)
        def solve(self, *a, **k):
            calls.append(1)
            return orig.solve(*a, **k)
    S.solver.cache._cache[(obj.name, d.uid)].native = Spy()
    for _ in range(5):
        bpy.context.view_layer.update()
        S.evaluated_positions(obj)
    R.check("no re-solve when nothing changed", len(calls) == 0, len(calls))
    e.location.z += 0.1
    bpy.context.view_layer.update()
    S.evaluated_positions(obj)
    R.check("exactly one solve per handle move", len(calls) == 1, len(calls))


def test_vertex_cloud():
    """A mesh without faces: the methods that need a surface refuse it at Add, by name;
    those whose registry entry says needs_faces=False (embedded deformation) deform it."""
    S.reset_scene()
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-1, 1, (800, 2)), np.zeros(800)]
    me = bpy.data.meshes.new("Cloud")
    me.from_pydata(pts.tolist(), [], [])
    obj = bpy.data.objects.new("Cloud", me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    for m in S.methods.METHODS:
        if m.needs_faces:
            try:
                bpy.ops.deformkit.add_deformer(method=m.id)
                refused = False
            except RuntimeError as ex:
                refused = "no faces" in str(ex) and m.label in str(ex)
            R.check("%s refuses a vertex cloud at Add" % m.id, refused)
    cloud = [m for m in S.handle_methods() if not m.needs_faces]
    R.check("some method deforms vertex clouds", len(cloud) > 0)
    for m in cloud:  # each on a cloud of its own (deformers on one would add up)
        S.reset_scene()
        me = bpy.data.meshes.new("Cloud")
        me.from_pydata(pts.tolist(), [], [])
        obj = bpy.data.objects.new("Cloud", me)
        bpy.context.scene.collection.objects.link(obj)
        bpy.context.view_layer.objects.active = obj
        S.group(obj, "fixed", np.where(pts[:, 0] < -0.9)[0])
        S.group(obj, "tip", np.where(pts[:, 0] > 0.9)[0])
        e = S.empty("CloudTip", (1.0, 0.0, 0.0))
        bpy.ops.deformkit.add_deformer(method=m.id)
        d = obj.deformkit.deformers[-1]
        d.fixed_group = "fixed"
        bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
        bpy.ops.deformkit.bind()
        R.check("%s binds a vertex cloud" % m.id, d.bound and not d.status_is_error, d.status)
        e.location.z += 0.3
        bpy.context.view_layer.update()
        got = S.evaluated_positions(obj)
        tip = np.where(pts[:, 0] > 0.9)[0]
        R.check("%s moves the cloud's handle points" % m.id,
                np.abs(got[tip, 2] - 0.3).max() < 0.03, np.abs(got[tip, 2] - 0.3).max())


def test_geodesic_influence():
    """Embedded deformation's Influence option and cut groups reach the solver: on a strip folded into a
    hairpin (a "hand" arm lying 0.2 above a "leg" arm, joined through a fixed bend), lifting
    the hand's tip drags the leg below it in Euclidean distance and leaves it in place along
    the surface (the behaviour is tested in depth in tests/python/test_embedded.py)."""
    S.reset_scene()
    arm, gap, width, step = 4.0, 0.2, 0.5, 0.05
    r = gap / 2
    length = 2 * arm + np.pi * r
    s = np.linspace(0, length, int(round(length / step)) + 1)
    x = np.where(s <= arm, s, np.where(s >= arm + np.pi * r, 2 * arm + np.pi * r - s,
                                       arm + r * np.sin((s - arm) / r)))
    z = np.where(s <= arm, 0.0, np.where(s >= arm + np.pi * r, gap,
                                         r - r * np.cos((s - arm) / r)))
    nw = int(round(width / step)) + 1
    pts = [(x[i], y, z[i]) for i in range(len(s)) for y in np.linspace(0, width, nw)]
    quads = [(i * nw + j, (i + 1) * nw + j, (i + 1) * nw + j + 1, i * nw + j + 1)
             for i in range(len(s) - 1) for j in range(nw - 1)]
    me = bpy.data.meshes.new("Hairpin")
    me.from_pydata(pts, [], quads)
    obj = bpy.data.objects.new("Hairpin", me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    arc = np.repeat(s, nw)
    leg, tip = np.where(arc < 0.5)[0], np.where(arc > length - 0.25)[0]
    S.group(obj, "bend", np.where(np.abs(arc - (arm + 0.16)) < 0.6)[0])
    S.group(obj, "tip", tip)
    e = S.empty("HandTip", (0.0, 0.0, 0.0))
    bpy.ops.deformkit.add_deformer(method="EMBEDDED")
    d = obj.deformkit.deformers[-1]
    d.fixed_group = "bend"
    d.options_embedded.n_nodes = 120
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    moved = {}
    for distance in ("euclidean", "geodesic"):
        d.options_embedded.distance = distance
        e.location = (0.0, 0.0, 0.0)
        bpy.ops.deformkit.bind()
        R.check("binds with %s influence" % distance, d.bound and not d.status_is_error,
                d.status)
        e.location.z = 0.5
        bpy.context.view_layer.update()
        got = S.evaluated_positions(obj)
        moved[distance] = np.abs(got[leg] - np.asarray(pts)[leg]).max()
    R.check("Euclidean influence drags the leg", moved["euclidean"] > 0.1, moved)
    R.check("geodesic influence leaves the leg", moved["geodesic"] < 1e-3, moved)
    # the cut groups (Euclidean influence): a cut between the arms does what geodesics do
    S.group(obj, "leg", np.where(arc < arm - 0.3)[0])
    S.group(obj, "hand", np.where(arc > arm + np.pi * r + 0.3)[0])
    d.options_embedded.distance = "euclidean"
    d.options_embedded.cut_a = "leg"
    e.location = (0.0, 0.0, 0.0)
    try:
        bpy.ops.deformkit.bind()
        msg = ""
    except RuntimeError as ex:
        msg = str(ex)
    R.check("one cut group alone is refused by name", "needs both" in msg and
            "Cut Side B" in msg, msg)
    d.options_embedded.cut_b = "hand"
    bpy.ops.deformkit.bind()
    R.check("binds with a cut", d.bound and not d.status_is_error, d.status)
    e.location.z = 0.5
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    cut_moved = np.abs(got[leg] - np.asarray(pts)[leg]).max()
    R.check("the cut leaves the leg", cut_moved < 1e-3, cut_moved)


def test_show_graph():
    """Show Graph: the overlay's draw handler is registered; a bound deformer with the
    toggle on gives its nodes where eq. 1 takes them (g + factor t, in world space) and its
    edges; toggling it neither rebinds nor changes the mesh; off, or unbound, draws nothing."""
    R.check("the viewport draw handler is registered", S.overlay._state["handle"] is not None)
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("EMBEDDED")
    obj.location = (0.5, -2.0, 1.0)
    bpy.context.view_layer.update()
    R.check("unbound: nothing to draw", S.overlay.graph_lines(obj, d) is None)
    bpy.ops.deformkit.bind()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    before = S.evaluated_positions(obj)
    native = S.solver.cache._cache[(obj.name, d.uid)].native
    R.check("toggle off: nothing to draw", S.overlay.graph_lines(obj, d) is None)
    d.options_embedded.show_graph = True
    bpy.context.view_layer.update()
    r = S.overlay.graph_lines(obj, d)
    R.check("toggle on: the graph", r is not None)
    if r is not None:
        pts, edges = r
        g = np.asarray(native.nodes)
        t = np.asarray(native.transforms)[:, 9:12]
        fac = S.geonodes.factor(obj, d)
        mw = np.array(obj.matrix_world)
        want = (g + fac * t) @ mw[:3, :3].T + mw[:3, 3]
        R.check("nodes at g + factor t in world space", pts.shape == g.shape and
                np.abs(pts - want).max() < 1e-12, np.abs(pts - want).max())
        R.check("the graph's edges", np.array_equal(edges, np.asarray(native.edges)) and
                len(edges) > 0)
        R.check("the nodes moved with the drag", np.abs(t).max() > 1e-3)
    R.check("toggling does not rebind", S.solver.cache._cache[(obj.name, d.uid)].native is native)
    R.check("toggling does not change the mesh",
            np.abs(S.evaluated_positions(obj) - before).max() < 1e-7)
    d.options_embedded.show_graph = False
    draw_graph_offscreen()


def draw_graph_offscreen():
    """Show Graph's drawing, offscreen where Blender as a module can draw (5.x: gpu.init):
    two nodes and their edge in a 64 x 64 frame. Each node must cover about NODE_SIZE^2
    pixels (5.3's Vulkan draws UNIFORM_COLOR points 1 pixel wide), the edge must show
    between them, and no deprecation warning may be raised. Debian's Blender draws the
    real viewport in screenshot_ui."""
    import warnings
    import gpu
    from mathutils import Matrix
    if not (S.AS_MODULE and hasattr(gpu, "init")):
        print("note: no offscreen drawing in this Blender (Blender as a module before 5.0, "
              "or the blender program headless)")
        return
    gpu.init()
    pts = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]])
    off = gpu.types.GPUOffScreen(64, 64)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with off.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0))
            with gpu.matrix.push_pop():
                gpu.matrix.load_matrix(Matrix.Identity(4))
                gpu.matrix.load_projection_matrix(Matrix.Identity(4))
                S.overlay.draw_graphs([(pts, np.array([[0, 1]], np.int32))])
            buf = np.array(fb.read_color(0, 0, 64, 64, 4, 0, "FLOAT").to_list())
    off.free()
    node = np.abs(buf[..., :3] - np.array(S.overlay.NODE_COLOR[:3])).max(axis=-1) < 0.02
    edge = buf[:, 22:42, 3] > 0   # between the nodes (at columns 16 and 48): the edge only
    want = 0.6 * 2 * S.overlay.NODE_SIZE ** 2
    R.check("Show Graph draws each node about %g pixels wide" % S.overlay.NODE_SIZE,
            node.sum() >= want, (int(node.sum()), want))
    R.check("Show Graph draws the edge between the nodes", edge.sum() >= 20, int(edge.sum()))
    R.check("Show Graph's drawing raises no deprecation warning", not caught,
            [str(w.message) for w in caught])


def test_eigen_region_and_preview():
    """Eigen deformation in the add-on: the Region group is R, moved by the handle's target;
    while dragging (UI-style updates) the viewport shows the fast preview (Steps 1-2), and
    the timer replaces it by the full result once the handle has stopped; both equal the
    direct API. A second handle with a Region group is refused in the panel."""
    import time
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("EIGEN", nx=24, ny=8)
    rest = S.rest_positions(obj)
    half = np.where(rest[:, 0] > 0.3)[0]
    S.group(obj, "half", half)
    d.roi_group = "half"
    bind_world = e.matrix_world.copy()
    bpy.ops.deformkit.bind()
    R.check("EIGEN with a Region group binds", d.bound and not d.status_is_error, d.status)
    m = S.methods.get("EIGEN")
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    native = S.dk.EigenDeformation(mesh, handles=[half], fixed=fixed, **m.region_kw,
                                   **S.methods.bind_kwargs(m, d.options, rest,
                                                           dict(handles=[half], fixed=fixed),
                                                           mesh))
    S.handlers.force_interactive[0] = True
    try:
        e.location = (1.0, 0.0, 0.3)
        e.rotation_euler = Euler((0.4, 0.0, 0.0))
        bpy.context.view_layer.update()
        T = np.array(e.matrix_world @ bind_world.inverted())[None]
        got = S.evaluated_positions(obj)
        want = np.asarray(native.solve(transforms=T, preview=True).positions)
        R.check("EIGEN drag shows the preview (Steps 1-2)", np.abs(got - want).max() < TOL,
                np.abs(got - want).max())
        key = (obj.name, d.uid)
        R.check("EIGEN preview is pending, and the panel says it is a preview",
                key in S.solver.pending() and S.solver.previewing(obj, d))
        S.handlers.refine()
        R.check("EIGEN full result waits while the handle may still move",
                key in S.solver.pending())
        time.sleep(S.solver.budget.PREVIEW_SETTLE_S + 0.05)
        while S.handlers.refine() is not None:
            pass
        got = S.evaluated_positions(obj)
        want = np.asarray(native.solve(transforms=T).positions)
        R.check("EIGEN full result once the handle stops", np.abs(got - want).max() < TOL
                and np.abs(want - rest).max() > 0.1, np.abs(got - want).max())
        R.check("EIGEN full result: the panel no longer says preview",
                not S.solver.previewing(obj, d))
    finally:
        S.handlers.force_interactive[0] = False
    d.roi_group = ""  # no Region group: the handle drags its part (region="part")
    bpy.context.view_layer.update()
    S.solver.evaluate_object(obj, check_groups=True)
    part = S.dk.EigenDeformation(mesh, handles=[handle], fixed=fixed,
                                 **S.methods.bind_kwargs(m, d.options, rest,
                                                         dict(handles=[handle], fixed=fixed),
                                                         mesh))
    got = S.evaluated_positions(obj)
    want = np.asarray(part.solve(transforms=T).positions)
    R.check("EIGEN without a Region group: the handle drags its part",
            np.abs(got - want).max() < TOL and not d.status_is_error,
            (np.abs(got - want).max(), d.status))
    d.roi_group = "half"
    S.group(obj, "tip2", handle[:3])
    e2 = S.empty("Tip2", (1.0, 0.0, 0.0))
    bpy.ops.deformkit.add_handle(vertex_group="tip2", target=e2.name)
    bpy.context.view_layer.update()
    S.solver.evaluate_object(obj, check_groups=True)
    R.check("EIGEN: two handles with a Region group are refused in the panel",
            d.status_is_error and "one handle" in d.status, d.status)



def test_linear_reconstruction_material_paint():
    """Linear reconstruction's Material group: the paint becomes the per-edge material map
    (Interpolate: harmonic through the painted vertices, as built at the handle and the fixed
    part; value 20 ** (softness * weight)), equal to the direct API with that map; the soft
    ring concentrates the fold; re-painting re-binds."""
    S.reset_scene()
    n_around, n_along = 16, 30
    a = 2 * np.pi * np.arange(n_around) / n_around
    verts = [(6.0 * j / (n_along - 1), 0.5 * np.cos(t), 0.5 * np.sin(t))
             for j in range(n_along) for t in a]
    faces = [(j * n_around + i, j * n_around + (i + 1) % n_around,
              (j + 1) * n_around + (i + 1) % n_around, (j + 1) * n_around + i)
             for j in range(n_along - 1) for i in range(n_around)]
    me = bpy.data.meshes.new("Tube")
    me.from_pydata(verts, [], faces)
    me.update()
    obj = bpy.data.objects.new("Tube", me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    v = np.array(verts)
    fixed, hand = np.where(v[:, 0] < 0.5)[0], np.where(v[:, 0] > 5.5)[0]
    elbow = np.where(np.abs(v[:, 0] - 3.0) < 0.45)[0]
    S.group(obj, "fixed", fixed)
    S.group(obj, "hand", hand)
    S.group(obj, "elbow", elbow)
    e = S.empty("Hand", (3.0, 0.0, 0.0))   # the pivot: the elbow
    bpy.ops.deformkit.add_deformer(method="LINEAR_RECONSTRUCTION")
    d = obj.deformkit.deformers[0]
    d.fixed_group = "fixed"
    bpy.ops.deformkit.add_handle(vertex_group="hand", target=e.name)
    bpy.ops.deformkit.bind()
    e.rotation_euler = Euler((0.0, -np.pi / 2, 0.0))
    bpy.context.view_layer.update()
    plain = S.evaluated_positions(obj)
    d.material_group = "elbow"
    bpy.context.view_layer.update()
    S.solver.evaluate_object(obj, check_groups=True)
    got = S.evaluated_positions(obj)
    R.check("LINEAR_RECONSTRUCTION re-binds with the painted material",
            not d.status_is_error and np.abs(got - plain).max() > 1e-3, d.status)
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    held = np.setdiff1d(np.r_[hand, fixed], elbow)
    mat = S.dk.harmonic_material(mesh, np.r_[elbow, held],
                                 np.r_[np.full(len(elbow), 20.0), np.ones(len(held))])
    T = np.array(e.matrix_world) @ np.linalg.inv(np.array(Matrix.Translation((3, 0, 0))))
    native = S.dk.LinearReconstruction(mesh, handles=[hand], fixed=fixed, material=mat)
    want = np.asarray(native.solve(transforms=[T]).positions)
    R.check("LINEAR_RECONSTRUCTION material paint = the API with harmonic_material",
            np.abs(got - want).max() < TOL, np.abs(got - want).max())

    def share(x):
        c = x.reshape(-1, n_around, 3).mean(axis=1)
        t = np.diff(c, axis=0)
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        b = np.arccos(np.clip((t[1:] * t[:-1]).sum(1), -1, 1))
        return b[10:18].sum() / b.sum()
    R.check("LINEAR_RECONSTRUCTION: the soft elbow takes more of the fold (%.0f%% -> %.0f%%)"
            % (100 * share(plain), 100 * share(got)), share(got) > share(plain) + 0.1)
    # Show Material: the map as the active colour attribute, yellow at the elbow
    name = "dk_%s_material" % d.uid
    d.options.show_material = True
    bpy.context.view_layer.update()   # the tick alone, no handle moved
    ca = obj.data.color_attributes.get(name)
    ok = ca is not None and obj.data.color_attributes.active_color.name == name
    if ok:
        col = np.empty(len(obj.data.vertices) * 4, np.float32)
        ca.data.foreach_get("color", col)
        col = col.reshape(-1, 4)
        ok = np.median(col[elbow, 2]) < 0.2 and np.median(col[fixed, 2]) > 0.4
        detail = (np.median(col[elbow, 2]), np.median(col[fixed, 2]))
    else:
        detail = "no attribute" if ca is None else "not active"
    R.check("LINEAR_RECONSTRUCTION Show Material paints the map (elbow yellow, ends grey)",
            ok, detail)
    d.options.show_material = False
    bpy.context.view_layer.update()   # the untick alone
    R.check("LINEAR_RECONSTRUCTION Show Material off removes the colours",
            obj.data.color_attributes.get(name) is None)


for t in (test_linear_reconstruction_material_paint, test_eigen_region_and_preview, test_vertex_cloud, test_geodesic_influence, test_show_graph, test_registry_drives_ui, test_methods, test_stiffness_map, test_soft_handles,
          test_bone_target, test_auto_rebind_on_group_change, test_skip_when_unchanged,
          test_bind_pose_of_transformed_object):
    R.run(t)
R.finish()

"""Every bad setup gives a clear message (operator error / deformer status), never a traceback,
and never writes garbage: empty or missing vertex groups, a handle with no target, a handle
overlapping the fixed group, no handles, deleted targets, non-mesh objects, meshes with no
faces, a topology change since bind, Edit Mode."""
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import bmesh  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_addon_setup_errors")
MID = next((m.id for m in S.methods.METHODS if S.native.has_class(m.native_class)), "ARAP")


def expect_error(what, fn, needle):
    try:
        fn()
    except RuntimeError as ex:  # bpy.ops raises the operator's ERROR report as RuntimeError
        msg = str(ex)
        R.check("%s: %r" % (what, msg.strip()), needle in msg and "Traceback" not in msg, msg)
        return msg
    R.check("%s: error expected" % what, False)


def fresh():
    S.reset_scene()
    return S.grid_setup(MID)


def test_no_handles():
    obj, d, e, fixed, handle = fresh()
    d.handles.clear()
    expect_error("no handles", bpy.ops.deformkit.bind, "no handles")
    R.check("status shows the error", d.status_is_error and "no handles" in d.status)


def test_missing_group():
    obj, d, e, fixed, handle = fresh()
    d.handles[0].vertex_group = "nope"
    expect_error("missing handle group", bpy.ops.deformkit.bind, "'nope' does not exist")
    d.handles[0].vertex_group = ""
    expect_error("handle without group", bpy.ops.deformkit.bind, "has no vertex group")
    d.handles[0].vertex_group = "tip"
    d.fixed_group = "gone"
    expect_error("missing fixed group", bpy.ops.deformkit.bind, "fixed vertex group 'gone' does not exist")


def test_empty_group():
    obj, d, e, fixed, handle = fresh()
    obj.vertex_groups.new(name="empty")
    d.handles[0].vertex_group = "empty"
    expect_error("empty handle group", bpy.ops.deformkit.bind, "is empty")
    d.handles[0].vertex_group = "tip"
    d.fixed_group = "empty"
    expect_error("empty fixed group", bpy.ops.deformkit.bind, "is empty")


def test_no_target():
    obj, d, e, fixed, handle = fresh()
    d.handles[0].target = None
    expect_error("handle without target", bpy.ops.deformkit.bind, "has no target")


def test_overlap_fixed():
    obj, d, e, fixed, handle = fresh()
    S.group(obj, "tip", [int(fixed[0])])
    expect_error("handle overlapping fixed", bpy.ops.deformkit.bind, "overlaps the fixed group")


def test_handles_overlap():
    obj, d, e, fixed, handle = fresh()
    S.group(obj, "tip2", [int(handle[0]), int(handle[0]) - 3])
    bpy.ops.deformkit.add_handle(vertex_group="tip2", target=e.name)
    expect_error("two handles sharing a vertex", bpy.ops.deformkit.bind, "share 1 vertex: a vertex can follow one handle only")


def test_deleted_target_after_bind():
    obj, d, e, fixed, handle = fresh()
    bpy.ops.deformkit.bind()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    bpy.data.objects.remove(e)
    bpy.context.view_layer.update()
    ok = d.status_is_error and ("no target" in d.status or "deleted" in d.status)
    R.check("deleted target reported in status: %r" % d.status, ok, d.status)
    p = S.evaluated_positions(obj)
    R.check("no garbage written (rest shape shown)", np.abs(p - S.rest_positions(obj)).max() < 1e-6)
    # unlinking from the scene (delete in the outliner keeps the datablock while referenced)
    obj, d, e, fixed, handle = fresh()
    bpy.ops.deformkit.bind()
    bpy.context.scene.collection.objects.unlink(e)
    bpy.context.view_layer.update()
    R.check("unlinked target reported: %r" % d.status, d.status_is_error and "deleted" in d.status)


def test_non_mesh():
    S.reset_scene()
    cu = bpy.data.curves.new("C", "CURVE")
    o = bpy.data.objects.new("Curve", cu)
    bpy.context.scene.collection.objects.link(o)
    bpy.context.view_layer.objects.active = o
    expect_error("non-mesh object", lambda: bpy.ops.deformkit.add_deformer(method=MID), "mesh objects")
    e = S.empty("E")
    bpy.context.view_layer.objects.active = e
    expect_error("empty object", lambda: bpy.ops.deformkit.bind(), "mesh objects")


def test_no_faces():
    S.reset_scene()
    me = bpy.data.meshes.new("pts")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1)], [])
    o = bpy.data.objects.new("Pts", me)
    bpy.context.scene.collection.objects.link(o)
    bpy.context.view_layer.objects.active = o
    expect_error("mesh without faces", lambda: bpy.ops.deformkit.add_deformer(method=MID), "no faces")


def test_topology_change():
    obj, d, e, fixed, handle = fresh()
    bpy.ops.deformkit.bind()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    n = len(obj.data.vertices)
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:3], cuts=1)
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()
    bpy.context.view_layer.update()
    m = len(obj.data.vertices)
    want = "mesh changed from %d to %d vertices: bind again" % (n, m)
    R.check("topology change reported: %r" % d.status, d.status == want and d.status_is_error, d.status)
    p = S.evaluated_positions(obj)
    R.check("no garbage after topology change (rest shape)",
            np.abs(p - S.rest_positions(obj)).max() < 1e-6)
    expect_error("solve after topology change via bake", lambda: bpy.ops.deformkit.apply(mode="MESH"),
                 "bind again")
    bpy.ops.deformkit.bind()
    R.check("bind again clears the error", d.bound and not d.status_is_error, d.status)


class _Reports:
    """Stands in for an operator: records what it reports."""
    def __init__(self):
        self.reports = []

    def report(self, kind, msg):
        self.reports.append((set(kind), msg))


def test_bind_reports_native_warnings():
    """Loose geometry is held at rest (docs/python-api.md): the bind's report says so in the
    report bar, as a warning, and a clean bind's report is plain information."""
    from addon import operators
    obj, d, e, fixed, handle = fresh()
    bpy.ops.deformkit.bind()
    op = _Reports()
    operators._report_bound(op, obj, d, 1.0)
    R.check("clean bind: an INFO report, no warning: %r" % op.reports,
            S.solver.bind_warnings(obj, d) == () and op.reports and op.reports[-1][0] == {"INFO"})
    n = S.add_loose_vertex(obj, (5.0, 5.0, 5.0))
    bpy.ops.deformkit.bind()
    w = S.solver.bind_warnings(obj, d)
    R.check("loose vertex: the native warning %r" % (w,),
            len(w) == 1 and "held at rest (first: vertex %d)" % n in w[0])
    operators._report_bound(op, obj, d, 1.0)
    kind, msg = op.reports[-1]
    R.check("loose vertex: a WARNING report with it: %r" % msg,
            kind == {"WARNING"} and "but 1 vertex in 1 connected component" in msg)


def test_edit_mode_is_skipped():
    obj, d, e, fixed, handle = fresh()
    bpy.ops.deformkit.bind()
    bpy.ops.object.mode_set(mode="EDIT")
    e.location.z += 0.3
    bpy.context.view_layer.update()   # must not touch the edit mesh or raise
    expect_error("bind in edit mode", bpy.ops.deformkit.bind, "Edit Mode")
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.update()
    p = S.evaluated_positions(obj)
    R.check("solved after leaving edit mode", abs((p - S.rest_positions(obj))[handle, 2].mean() - 0.3) < 1e-4)


def test_no_deformer():
    S.reset_scene()
    S.make_grid()
    expect_error("bind without deformer", bpy.ops.deformkit.bind, "no DeformKit deformer")


def test_add_handle_from_selection():
    S.reset_scene()
    obj = S.make_grid()
    bpy.ops.object.mode_set(mode="EDIT")
    expect_error("nothing selected", lambda: (bpy.ops.mesh.select_all(action="DESELECT"),
                                              bpy.ops.deformkit.add_handle_from_selection())[1],
                 "no vertices selected")
    bm = bmesh.from_edit_mesh(obj.data)
    sel = [v.index for v in bm.verts if v.co.x > 0.8]
    for v in bm.verts:
        v.select = v.co.x > 0.8
    bmesh.update_edit_mesh(obj.data)
    bpy.ops.deformkit.add_handle_from_selection(method=MID)
    bpy.ops.object.mode_set(mode="OBJECT")
    d = obj.deformkit.deformers[0]
    h = d.handles[0]
    vg = obj.vertex_groups.get(h.vertex_group)
    members = sorted(v.index for v in obj.data.vertices if any(g.group == vg.index for g in v.groups))
    R.check("handle group = selection", members == sorted(sel))
    rest = S.rest_positions(obj)
    c = rest[sel].mean(axis=0)
    R.check("empty at the selection centre", h.target is not None
            and np.abs(np.array(h.target.location) - c).max() < 1e-5)
    R.check("deformer and modifier created", S.geonodes.find_modifier(obj, d) is not None)
    expect_error("add handle from selection outside edit mode",
                 bpy.ops.deformkit.add_handle_from_selection, "Edit Mode")


def test_linked_objects_are_refused():
    """An object linked from another .blend (and an override whose mesh stays linked): Bind
    and Apply reported success and wrote nothing, Apply removing the deformer (the second
    hostile review). Every operator now refuses it by name, and nothing changes."""
    obj, d, e, fixed, handle = fresh()
    bpy.ops.deformkit.bind()
    lib = os.path.join(S.OUTPUT, "setup_errors_library.blend")
    bpy.ops.wm.save_as_mainfile(filepath=lib)
    name = obj.name
    S.reset_scene()
    with bpy.data.libraries.load(lib, link=True) as (src, dst):
        dst.objects = [n for n in src.objects if n == name]
    linked = dst.objects[0]
    bpy.context.scene.collection.objects.link(linked)
    bpy.context.view_layer.objects.active = linked
    R.check("the object is linked", linked.library is not None)
    n_def = len(linked.deformkit.deformers)
    for label, op in (("Bind", bpy.ops.deformkit.bind), ("Apply", bpy.ops.deformkit.apply),
                      ("Remove", bpy.ops.deformkit.remove_deformer),
                      ("Add", lambda: bpy.ops.deformkit.add_deformer(method=MID))):
        expect_error("%s on a linked object" % label, op, "is linked from the library")
    R.check("nothing changed: the linked object keeps its deformer",
            len(linked.deformkit.deformers) == n_def == 1)


def test_a_control_kind_the_addon_cannot_read():
    """A method whose native table declares only control kinds the add-on has no collector
    for (as a method bound to example poses would, in a module newer than the add-on) is refused at Bind by
    name, and nothing is bound; the add-on picks the collector from the table, not from the
    method's name."""
    obj, d, e, fixed, handle = fresh()
    real = S.native.method_info
    cls = S.methods.get(d.method).native_class

    def poses_only(name):
        info = real(name)
        return dict(info, controls=("poses",)) if name == cls else info
    S.native.method_info = poses_only
    try:
        expect_error("a method bound to poses", bpy.ops.deformkit.bind,
                     "binds to poses, which this version of the add-on cannot read")
        R.check("nothing bound", not d.bound and d.status_is_error, d.status)
    finally:
        S.native.method_info = real
    bpy.ops.deformkit.bind()
    R.check("the vertex groups bind again", d.bound and not d.status_is_error, d.status)


for t in (test_linked_objects_are_refused, test_a_control_kind_the_addon_cannot_read, test_no_handles, test_missing_group, test_empty_group, test_no_target, test_overlap_fixed, test_handles_overlap,
          test_deleted_target_after_bind, test_non_mesh, test_no_faces, test_topology_change,
          test_bind_reports_native_warnings,
          test_edit_mode_is_skipped, test_no_deformer, test_add_handle_from_selection):
    R.run(t)
R.finish()

"""The deformers driven by a control object (issue 40): a Lattice object drives the Lattice
deformer, any closed mesh the Cage deformer. Their results equal the Python API's, the linear
lattice equals Blender's own Lattice modifier vertex for vertex, the control's object motion
carries the mesh, Make Lattice and Make Cage enclose it, an Armature's pose is edited (the
lattice) or has the rest's offset pasted on (the cage), a save and reload keeps the result,
and what goes wrong is said in the deformer's status."""
import os
import subprocess
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Euler, Matrix  # noqa: E402

R = S.Results("test_addon_controls")
TOL = 2e-5  # float32 attribute storage


def _lattice_points(lt, attr):
    a = np.empty(len(lt.points) * 3, np.float32)
    lt.points.foreach_get(attr, a)
    return a.reshape(-1, 3).astype(np.float64)


def lattice_setup(interpolation="bspline", outside="extend", counts=(3, 3, 3), make=True):
    S.reset_scene()
    obj = S.make_grid(nx=16, ny=8)
    obj.location = (0.3, -0.2, 0.1)
    obj.rotation_euler = Euler((0.2, 0.1, 0.4))
    bpy.context.view_layer.update()
    bpy.ops.deformkit.add_deformer(method="LATTICE")
    d = obj.deformkit.deformers[0]
    d.options.interpolation = interpolation
    d.options.outside = outside
    if make:
        bpy.ops.deformkit.make_lattice(resolution=counts)
    return obj, d


def blender_lattice_twin(obj, lat):
    """A copy of obj's mesh with Blender's Lattice modifier on `lat` (and no DeformKit)."""
    twin = bpy.data.objects.new("Twin", obj.data.copy())
    bpy.context.scene.collection.objects.link(twin)
    twin.matrix_world = obj.matrix_world
    for a in list(twin.data.attributes):
        if a.name.startswith("dk_"):
            twin.data.attributes.remove(a)
    m = twin.modifiers.new("Lattice", "LATTICE")
    m.object = lat
    return twin


def test_make_lattice_encloses_and_binds():
    obj, d = lattice_setup()
    lat = d.control_object
    R.check("Make Lattice sets the control", lat is not None and lat.type == "LATTICE")
    R.check("the lattice rides the mesh", lat.parent == obj)
    # every vertex inside the lattice's box (in the lattice's space)
    M = np.array(lat.matrix_world.inverted() @ obj.matrix_world)
    local = S.rest_positions(obj) @ M[:3, :3].T + M[:3, 3]
    co = _lattice_points(lat.data, "co")
    inside = (local >= co.min(0) - 1e-9).all() and (local <= co.max(0) + 1e-9).all()
    R.check("Make Lattice encloses the mesh", inside)
    bpy.ops.deformkit.bind()
    R.check("bound", d.bound and not d.status_is_error, d.status)
    R.check("status names the lattice", "lattice '%s'" % lat.name in S.solver.status_text(d),
            S.solver.status_text(d))
    err = np.abs(S.evaluated_positions(obj) - S.rest_positions(obj)).max()
    R.check("at bind = rest (%.1e)" % err, err < TOL)


def test_linear_lattice_equals_blenders():
    """Linear interpolation and clamp: vertex for vertex Blender's Lattice modifier with the
    same lattice at linear interpolation, after editing points, for a full and a flat one."""
    for counts in ((3, 4, 2), (4, 3, 1)):
        obj, d = lattice_setup("linear", "clamp", counts)
        lat = d.control_object
        for attr in ("interpolation_type_u", "interpolation_type_v", "interpolation_type_w"):
            setattr(lat.data, attr, "KEY_LINEAR")
        bpy.ops.deformkit.bind()
        twin = blender_lattice_twin(obj, lat)
        rng = np.random.default_rng(3)
        cd = _lattice_points(lat.data, "co_deform") + rng.normal(0, 0.15, (len(lat.data.points), 3))
        lat.data.points.foreach_set("co_deform", cd.astype(np.float32).ravel())
        lat.data.update_tag()
        bpy.context.view_layer.update()
        got, want = S.evaluated_positions(obj), S.evaluated_positions(twin)
        moved = np.abs(want - S.rest_positions(obj)).max()
        err = np.abs(got - want).max()
        R.check("%s lattice = Blender's Lattice modifier (%.1e, moved %.2f)" % (counts, err, moved),
                err < 1e-4 and moved > 0.05, d.status)


def _api_lattice(obj, d, targets, input_positions=None):
    m = S.methods.get(d.method)
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    kw, _ = S.solver.controls.collect(obj, d)
    kw.update(S.methods.bind_kwargs(m, d.options, rest, kw, mesh))
    lat = S.dk.Lattice(mesh, **kw)
    return np.asarray(lat.solve(targets, input_positions=input_positions).positions), lat


def test_lattice_follows_points_and_object():
    obj, d = lattice_setup()
    lat = d.control_object
    bpy.ops.deformkit.bind()
    cd = _lattice_points(lat.data, "co_deform")
    cd[13] += (0.0, 0.0, 0.4)    # the middle point up
    cd[0] += (-0.2, 0.1, 0.0)
    lat.data.points.foreach_set("co_deform", cd.astype(np.float32).ravel())
    lat.data.update_tag()
    bpy.context.view_layer.update()
    got = S.evaluated_positions(obj)
    # the native points, computed here: the lattice's points in the mesh's space
    M = np.array(obj.matrix_world.inverted() @ lat.matrix_world)
    targets = cd @ M[:3, :3].T + M[:3, 3]
    want, api = _api_lattice(obj, d, targets)
    rp = np.asarray(api.rest_points)
    co = _lattice_points(lat.data, "co") @ M[:3, :3].T + M[:3, 3]
    R.check("the native lattice's points are Blender's (%.1e)" % np.abs(rp - co).max(),
            np.abs(rp - co).max() < 1e-6)
    err = np.abs(got - want).max()
    R.check("edited points: add-on = API (%.1e, moved %.2f)"
            % (err, np.abs(want - S.rest_positions(obj)).max()), err < TOL, d.status)
    # the lattice's object turned and moved: the mesh goes with it, rigidly
    before = got
    A0 = lat.matrix_world.copy()
    lat.matrix_world = Matrix.Translation((0.2, -0.1, 0.3)) @ Matrix.Rotation(0.5, 4, "Z") @ A0
    bpy.context.view_layer.update()
    now = S.evaluated_positions(obj)
    Wm = np.array(obj.matrix_world)
    G = np.linalg.solve(Wm, np.array(lat.matrix_world @ A0.inverted()) @ Wm)
    want = before @ G[:3, :3].T + G[:3, 3]
    err = np.abs(now - want).max()
    R.check("the lattice's object motion carries the mesh (%.1e)" % err, err < TOL)


def _armature_on(obj, angle=0.6):
    """An Armature modifier (first in obj's stack) bending obj's right half about z."""
    arm, ao = S.armature_in_edit_mode("Rig")
    b = arm.edit_bones.new("b")
    b.head, b.tail = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)
    bpy.ops.object.mode_set(mode="OBJECT")
    rest = S.rest_positions(obj)
    S.group(obj, "b", range(len(rest)), np.clip((rest[:, 0] + 0.1) / 0.4, 0.0, 1.0))
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = ao
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.modifier_move_to_index(modifier="Armature", index=0)
    pb = ao.pose.bones["b"]
    pb.rotation_mode = "XYZ"
    pb.rotation_euler = (0.0, 0.0, angle)
    bpy.context.view_layer.update()
    return ao


def test_after_an_armature():
    """The lattice edits the pose it is given (the pose registered to the lattice where it
    lies); the cage solves on the rest and its offset lands on the pose."""
    obj, d = lattice_setup()
    lat = d.control_object
    bpy.ops.deformkit.bind()
    _armature_on(obj)
    pose = S.armature_input(obj, d)
    R.check("the armature poses the mesh", np.abs(pose - S.rest_positions(obj)).max() > 0.05)
    err = np.abs(S.evaluated_positions(obj) - pose).max()
    R.check("lattice at rest: the pose unchanged (%.1e)" % err, err < TOL)
    cd = _lattice_points(lat.data, "co_deform")
    cd[13] += (0.0, 0.0, 0.4)
    lat.data.points.foreach_set("co_deform", cd.astype(np.float32).ravel())
    lat.data.update_tag()
    bpy.context.view_layer.update()
    M = np.array(obj.matrix_world.inverted() @ lat.matrix_world)
    want, _ = _api_lattice(obj, d, cd @ M[:3, :3].T + M[:3, 3], input_positions=pose)
    err = np.abs(S.evaluated_positions(obj) - want).max()
    R.check("lattice after an Armature = API on the pose (%.1e)" % err, err < TOL, d.status)

    obj, d, cage = cage_setup()
    bpy.ops.deformkit.bind()
    _armature_on(obj)
    pose = S.armature_input(obj, d)
    V = _cage_co(cage)
    V[0] += (0.0, 0.0, 0.3)
    cage.data.vertices.foreach_set("co", V.astype(np.float32).ravel())
    cage.data.update()
    bpy.context.view_layer.update()
    alone = _api_cage(obj, d, cage)
    want = pose + (alone - S.rest_positions(obj))
    err = np.abs(S.evaluated_positions(obj) - want).max()
    R.check("cage after an Armature: its offset on the pose (%.1e)" % err, err < TOL, d.status)


def cage_setup(detail=1):
    S.reset_scene()
    import bmesh
    me = bpy.data.meshes.new("Blob")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=0.5)
    for v in bm.verts:
        v.co.x *= 1.6
        v.co.z += 0.05 * np.sin(6 * v.co.x)
    bm.to_mesh(me)
    bm.free()
    obj = S.linked_object("Blob", me)
    obj.location = (1.0, 2.0, -0.5)
    obj.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    bpy.ops.deformkit.add_deformer(method="CAGE")
    d = obj.deformkit.deformers[0]
    bpy.ops.deformkit.make_cage(detail=detail)
    return obj, d, d.control_object


def _cage_co(cage):
    co = np.empty(len(cage.data.vertices) * 3, np.float32)
    cage.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def _api_cage(obj, d, cage):
    rest = S.rest_positions(obj)
    mesh = S.dk.Mesh(rest, S.solver.triangles(obj.data))
    kw, _ = S.solver.controls.collect(obj, d)
    kw.update(S.methods.bind_kwargs(S.methods.get(d.method), d.options, rest, kw, mesh))
    api = S.dk.Cage(mesh, **kw)
    M = np.array(obj.matrix_world.inverted() @ cage.matrix_world)
    return np.asarray(api.solve(_cage_co(cage) @ M[:3, :3].T + M[:3, 3]).positions)


def test_cage():
    obj, d, cage = cage_setup()
    R.check("Make Cage sets the control", cage is not None and cage.type == "MESH"
            and cage.parent == obj and len(cage.data.vertices) == 42)
    bpy.ops.deformkit.bind()
    R.check("cage bound", d.bound and not d.status_is_error, d.status)
    rest = S.rest_positions(obj)
    err = np.abs(S.evaluated_positions(obj) - rest).max()
    R.check("cage at bind = rest (%.1e)" % err, err < TOL)
    V = _cage_co(cage)
    V[:5] += (0.0, 0.1, 0.2)
    cage.data.vertices.foreach_set("co", V.astype(np.float32).ravel())
    cage.data.update()
    bpy.context.view_layer.update()
    got, want = S.evaluated_positions(obj), _api_cage(obj, d, cage)
    err = np.abs(got - want).max()
    R.check("edited cage: add-on = API (%.1e, moved %.2f)" % (err, np.abs(want - rest).max()),
            err < TOL and np.abs(want - rest).max() > 0.02, d.status)
    # an affine map of the cage's vertices maps the mesh by it (linear precision)
    A = np.array([[1.2, 0.1, 0.0], [0.0, 0.9, 0.2], [0.1, 0.0, 1.1]])
    V0 = _cage_co(cage)
    V0[:5] -= (0.0, 0.1, 0.2)
    cage.data.vertices.foreach_set("co", (V0 @ A.T + 0.1).astype(np.float32).ravel())
    cage.data.update()
    bpy.context.view_layer.update()
    # cage space = mesh space scaled: the map in the mesh's space
    M = np.array(obj.matrix_world.inverted() @ cage.matrix_world)
    Am = M[:3, :3] @ A @ np.linalg.inv(M[:3, :3])
    bm = M[:3, :3] @ (0.1 * np.ones(3)) + M[:3, 3] - Am @ M[:3, 3]
    want = rest @ Am.T + bm
    err = np.abs(S.evaluated_positions(obj) - want).max()
    R.check("an affine cage maps the mesh by it (%.1e)" % err, err < 1e-4)
    # a vertex removed from the cage: the status asks for Bind; the mesh data is untouched
    import bmesh
    bm_ = bmesh.new()
    bm_.from_mesh(cage.data)
    bm_.verts.ensure_lookup_table()
    bmesh.ops.delete(bm_, geom=[bm_.verts[0]], context="VERTS")
    bm_.to_mesh(cage.data)
    bm_.free()
    cage.data.update()
    bpy.context.view_layer.update()
    R.check("a cage that lost a vertex asks for Bind",
            d.status_is_error and "press Bind" in d.status, d.status)
    R.check("the rest is untouched", np.array_equal(S.rest_positions(obj), rest))


def test_green_cage():
    """Green coordinates from the panel's option on Make Cage's cage: the add-on's result is
    the API's (their properties are tested in tests/native/test_cage.c and
    tests/python/test_cage.py)."""
    obj, d, cage = cage_setup()
    d.options.coordinates = "green"
    bpy.ops.deformkit.bind()
    R.check("green cage bound", d.bound and not d.status_is_error, d.status)
    V = _cage_co(cage)
    V[:6] += (0.05, 0.1, 0.15)
    cage.data.vertices.foreach_set("co", V.astype(np.float32).ravel())
    cage.data.update()
    bpy.context.view_layer.update()
    got, want = S.evaluated_positions(obj), _api_cage(obj, d, cage)
    err = np.abs(got - want).max()
    moved = np.abs(want - S.rest_positions(obj)).max()
    R.check("green: add-on = API (%.1e, moved %.2f)" % (err, moved),
            err < TOL and moved > 0.02, d.status)


def test_errors_are_said():
    obj, d = lattice_setup(make=False)
    try:
        bpy.ops.deformkit.bind()
        said = ""
    except RuntimeError as ex:   # the report bar's error (bpy as a module raises it)
        said = str(ex)
    R.check("no lattice: Bind says so", not d.bound and "no lattice" in said, said)
    R.check("idle status asks for a lattice", "Make Lattice" in S.solver.idle_status(d),
            S.solver.idle_status(d))
    bpy.ops.deformkit.make_lattice()
    bpy.ops.deformkit.bind()
    first = d.control_object
    bpy.ops.deformkit.make_lattice()   # another lattice picked after the bind
    bpy.context.view_layer.update()
    R.check("another lattice asks for Bind", d.status_is_error and "press Bind" in d.status,
            d.status)
    bpy.ops.deformkit.bind()
    R.check("Bind takes the new lattice", d.bound and not d.status_is_error
            and d.control_bound_object == d.control_object != first, d.status)
    bpy.data.objects.remove(d.control_object)
    bpy.context.view_layer.update()
    R.check("a deleted lattice is said", d.status_is_error and "lattice" in d.status.lower(),
            d.status)
    # the cage deformer refuses a lattice object and takes no handles
    R.check("the lattice poll refuses a mesh", not S.properties._control_poll(d, obj))


def test_save_and_reload():
    obj, d = lattice_setup()
    lat = d.control_object
    bpy.ops.deformkit.bind()
    cd = _lattice_points(lat.data, "co_deform")
    cd[4] += (0.1, 0.3, 0.0)
    lat.data.points.foreach_set("co_deform", cd.astype(np.float32).ravel())
    lat.data.update_tag()
    bpy.context.view_layer.update()
    before = S.evaluated_positions(obj)
    path = os.path.join(S.OUTPUT, "controls_reload.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    S.solver.clear_cache()
    bpy.ops.wm.open_mainfile(filepath=path)
    obj = bpy.data.objects["Grid"]
    d = obj.deformkit.deformers[0]
    R.check("reload keeps the lattice and its bind", d.control_object is not None
            and d.control_bind != "" and d.bound)
    cd = _lattice_points(d.control_object.data, "co_deform")
    cd[4] += (0.0, 0.0, 0.2)   # an edit after the reload solves with the kept bind
    d.control_object.data.points.foreach_set("co_deform", cd.astype(np.float32).ravel())
    d.control_object.data.update_tag()
    bpy.context.view_layer.update()
    M = np.array(obj.matrix_world.inverted() @ d.control_object.matrix_world)
    want, _ = _api_lattice(obj, d, cd @ M[:3, :3].T + M[:3, 3])
    err = np.abs(S.evaluated_positions(obj) - want).max()
    R.check("after reload an edit solves as before (%.1e)" % err, err < TOL, d.status)
    R.check("and differs from the saved result", np.abs(before - want).max() > 1e-3)


def test_an_animated_control_plays_and_bakes():
    """A lattice point hooked to a keyed empty (the lattice's own modifier) and a cage keyed
    as an object: each frame shows the API's solve for the control on that frame, the panel
    asks for a bake, and a Point Cache bake plays what playback showed."""
    obj, d = lattice_setup()
    lat = d.control_object
    bpy.ops.deformkit.bind()
    e = S.empty("Hook", (0.0, 0.0, 0.0))
    hook = lat.modifiers.new("Hook", "HOOK")
    hook.object = e
    hook.vertex_indices_set([13])
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 6
    for f, z in ((1, 0.0), (6, 0.5)):
        e.location = (0.0, 0.0, z)
        e.keyframe_insert("location", frame=f)
    R.check("the panel asks for a bake", "control" in (S.addon.bake.animated_reason(obj, d) or ""),
            S.addon.bake.animated_reason(obj, d))
    seen, worst = {}, 0.0
    for f in range(1, 7):
        sc.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        le = lat.evaluated_get(dg)
        M = np.array(obj.matrix_world.inverted() @ le.matrix_world)
        want, _ = _api_lattice(obj, d, _lattice_points(le.data, "co_deform") @ M[:3, :3].T
                               + M[:3, 3])
        seen[f] = S.evaluated_positions(obj)
        worst = max(worst, float(np.abs(seen[f] - want).max()))
    R.check("every frame = the API on that frame's lattice (%.1e)" % worst, worst < TOL)
    R.check("the hook moves the mesh", np.abs(seen[6] - seen[1]).max() > 0.05)
    path = os.path.join(S.OUTPUT, "controls_lattice.pc2")
    if os.path.exists(path):
        os.remove(path)
    bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=6, filepath=path)
    S.handlers.enabled[0] = False
    try:
        worst = 0.0
        for f in range(1, 7):
            sc.frame_set(f)
            worst = max(worst, float(np.abs(S.evaluated_positions(obj) - seen[f]).max()))
    finally:
        S.handlers.enabled[0] = True
    R.check("the bake plays what playback showed (%.1e)" % worst, worst < TOL)
    # a pipeline's batch bake of the saved scene (scripts/batch_bake.py, another process)
    # writes what playback showed
    bpy.ops.deformkit.free_bake()
    blend = os.path.join(S.OUTPUT, "controls_lattice.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    out = os.path.join(S.OUTPUT, "controls_lattice_batch.pc2")
    if os.path.exists(out):
        os.remove(out)
    batch = os.path.join(S.ROOT, "scripts", "batch_bake.py")
    args = ["--object", "Grid", "--frames", "1-6", "--out", out]
    cmd = ([sys.executable, batch, "--blend", blend] + args if S.AS_MODULE
           else S.blender_command(blend=blend, script=batch, args=args))
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    R.check("the batch bake exits 0", r.returncode == 0, r.stderr[-800:])
    if r.returncode == 0:
        from addon import pc2
        _, frames = pc2.read(out)
        worst = max(float(np.abs(np.asarray(fr, dtype=np.float64).reshape(-1, 3)
                                 - seen[i + 1]).max()) for i, fr in enumerate(frames))
        R.check("the batch bake = playback (%.1e, %d frames)" % (worst, len(frames)),
                len(frames) == 6 and worst < TOL)

    obj, d, cage = cage_setup()
    bpy.ops.deformkit.bind()
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = 1, 4
    base = cage.matrix_basis.copy()
    for f, ang in ((1, 0.0), (4, 0.6)):
        cage.matrix_basis = Matrix.Rotation(ang, 4, "X") @ base
        cage.keyframe_insert("rotation_euler", frame=f)
        cage.keyframe_insert("location", frame=f)
    sc.frame_set(4)
    rest = S.rest_positions(obj)
    want = _api_cage(obj, d, cage)
    err = np.abs(S.evaluated_positions(obj) - want).max()
    R.check("a keyed cage: frame 4 = the API (%.1e, moved %.2f)"
            % (err, np.abs(want - rest).max()), err < TOL and np.abs(want - rest).max() > 0.05)


def skinning_setup(blend):
    """A 24 x 6 grid, a two-bone armature (upper, lower) and vertex groups of the bones'
    names blending across the elbow; the Skinning deformer bound to it, and a copy of the
    mesh with Blender's Armature modifier on the same armature and groups."""
    S.reset_scene()
    obj = S.make_grid(nx=24, ny=6)
    obj.location = (0.2, 0.1, -0.3)
    rest = S.rest_positions(obj)
    w = np.clip((rest[:, 0] + 0.3) / 0.6, 0.0, 1.0)
    S.group(obj, "lower", range(len(rest)), w)
    S.group(obj, "upper", [i for i in range(len(rest)) if w[i] < 1.0],
            [1.0 - w[i] for i in range(len(rest)) if w[i] < 1.0])
    arm, ao = S.armature_in_edit_mode("Rig")
    up = arm.edit_bones.new("upper")
    up.head, up.tail = (-0.8, 0.1, -0.3), (0.2, 0.1, -0.3)
    lo = arm.edit_bones.new("lower")
    lo.head, lo.tail = (0.2, 0.1, -0.3), (1.2, 0.1, -0.3)
    lo.parent, lo.use_connect = up, True
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method="SKINNING")
    d = obj.deformkit.deformers[0]
    d.options.blend = blend
    d.control_object = ao
    bpy.ops.deformkit.bind()
    twin = bpy.data.objects.new("Twin", obj.data.copy())
    bpy.context.scene.collection.objects.link(twin)
    twin.matrix_world = obj.matrix_world
    for a in list(twin.data.attributes):
        if a.name.startswith("dk_"):
            twin.data.attributes.remove(a)
    for vg in obj.vertex_groups:
        twin.vertex_groups.new(name=vg.name)
    for v in obj.data.vertices:
        for g in v.groups:
            twin.vertex_groups[obj.vertex_groups[g.group].name].add([v.index], g.weight,
                                                                  "REPLACE")
    m = twin.modifiers.new("Armature", "ARMATURE")
    m.object = ao
    m.use_deform_preserve_volume = blend == "dual_quaternion"
    return obj, d, ao, twin


def test_skinning_equals_blenders_armature():
    """Linear blend skinning equals Blender's Armature modifier vertex for vertex, and dual
    quaternions its Preserve Volume, on a posed two-bone arm (a bend, a twist, the armature
    object moved)."""
    for blend in ("linear", "dual_quaternion"):
        obj, d, ao, twin = skinning_setup(blend)
        R.check("%s skinning bound" % blend, d.bound and not d.status_is_error, d.status)
        rest = S.rest_positions(obj)
        err = np.abs(S.evaluated_positions(obj) - rest).max()
        R.check("%s: the rest pose gives the mesh back (%.1e)" % (blend, err), err < TOL)
        for pb, rot in ((ao.pose.bones["upper"], (0.0, 0.3, 0.2)),
                        (ao.pose.bones["lower"], (1.4, 0.0, 0.9))):
            pb.rotation_mode = "XYZ"
            pb.rotation_euler = rot
        ao.location = (0.1, -0.2, 0.05)
        bpy.context.view_layer.update()
        got, want = S.evaluated_positions(obj), S.evaluated_positions(twin)
        err = np.abs(got - want).max()
        R.check("%s = Blender's Armature modifier (%.1e, moved %.2f)"
                % (blend, err, np.abs(want - rest).max()),
                err < 1e-4 and np.abs(want - rest).max() > 0.2, d.status)


def test_compute_weights():
    """Compute Weights writes bounded biharmonic weights of the armature's deforming bones
    into groups of their names (the native function's, limited to the influences), which the
    Skinning deformer and Blender's Armature modifier then read alike; without an armature it
    says so and writes nothing."""
    import deformkit as dk
    from addon import compute_weights as cw
    S.reset_scene()
    V, F = S.tube()
    obj = S.triangle_mesh_object(V, F, name="Tube")
    obj.location = (0.3, -0.1, 0.2)
    bpy.ops.deformkit.add_deformer(method="SKINNING")
    d = obj.deformkit.deformers[0]
    try:
        bpy.ops.deformkit.compute_weights()
        said = ""
    except RuntimeError as e:
        said = str(e)
    R.check("no armature: said, nothing written", "no armature" in said
            and len(obj.vertex_groups) == 0, said)
    arm, ao = S.two_bone_rig("Rig")
    ao.location = obj.location
    bpy.context.view_layer.objects.active = obj
    d.control_object = ao
    bpy.ops.deformkit.compute_weights(influences=2)
    names = [vg.name for vg in obj.vertex_groups]
    R.check("a group per bone", names == ["upper", "lower"], names)
    W = np.zeros((len(V), 2))
    for v in obj.data.vertices:
        for g in v.groups:
            W[v.index, g.group] = g.weight
    seg = cw.bone_segments(obj, ao)[1]
    R.check("the bones' segments in the mesh's space",
            np.abs(seg - [[[-1, 0, 0], [0, 0, 0]], [[0, 0, 0], [1, 0, 0]]]).max() < 1e-6, seg)
    want = cw.limit_influences(dk.bounded_biharmonic_weights(
        dk.Mesh(S.rest_positions(obj), F), bones=seg), 2)
    err = np.abs(W - want).max()
    R.check("the groups hold the native weights (%.1e)" % err, err < 1e-6)
    R.check("each vertex's weights sum to 1", np.abs(W.sum(1) - 1).max() < 1e-6)
    R.check("each bone's end is its own", W[V[:, 0] < -0.8, 0].min() > 0.9
            and W[V[:, 0] > 0.8, 1].min() > 0.9)
    bpy.ops.deformkit.bind()
    R.check("bound", d.bound and not d.status_is_error, d.status)
    twin = bpy.data.objects.new("Twin", obj.data.copy())
    bpy.context.scene.collection.objects.link(twin)
    twin.matrix_world = obj.matrix_world
    for vg in obj.vertex_groups:
        twin.vertex_groups.new(name=vg.name)
    m = twin.modifiers.new("Armature", "ARMATURE")
    m.object = ao
    pb = ao.pose.bones["lower"]
    pb.rotation_mode = "XYZ"
    pb.rotation_euler = (0.0, 0.0, 1.2)
    bpy.context.view_layer.update()
    got, want = S.evaluated_positions(obj), S.evaluated_positions(twin)
    err = np.abs(got - want).max()
    R.check("the deformer = Blender's Armature modifier on the computed groups (%.1e)" % err,
            err < 1e-4 and np.abs(want - V).max() > 0.3, d.status)


if __name__ == "__main__":
    for fn in (test_make_lattice_encloses_and_binds, test_linear_lattice_equals_blenders,
               test_lattice_follows_points_and_object, test_cage, test_green_cage,
               test_after_an_armature,
               test_errors_are_said, test_save_and_reload,
               test_an_animated_control_plays_and_bakes, test_skinning_equals_blenders_armature,
               test_compute_weights):
        R.run(fn)
    R.finish()

"""The artist's workflow (issue 17): baked states that show and can be undone, the panel
that stays with the handle, errors with a way out, plumbing out of view.

- Bake to Point Cache: the panel names the cache and says edits don't show; Free Bake removes
  the Mesh Cache and brings the live result back (an edit shows again); Re-bake bakes the same
  range again. Bake to Shape Keys shows the baked pose at once (it showed the rest shape until
  the frame changed); Free Bake removes its keys, their keyframes and the lone Basis.
- The sidebar (N) tab lists the active mesh's deformers, or those the selected handle target
  drives, with Bind; the target's Object tab says what it moves.
- An overlap error offers Select Shared and Remove from either group, which work; a deleted
  modifier gets Restore Modifier; an Attribute input edited in the modifier is found again by
  the modifier's name and repaired; Bind with the modifier off warns.
- Animated and not baked: the panel warns (a keyed target, a keyed Factor), and not once baked.
- No DeformKit panel on meshes without a deformer; no deformer entry in the Object menu for
  empties; the point cache's file is a field of the panel.
"""
import os
import shutil
import stat
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Matrix  # noqa: E402

R = S.Results("test_addon_workflow")
ui, bake = S.addon.ui, S.addon.bake


class Rec:
    """A layout that records the operators and labels a draw function asks for."""

    def __init__(self, out):
        self.__dict__["out"] = out

    def __setattr__(self, k, v):
        pass

    def _sub(self, *a, **kw):
        return Rec(self.out)

    row = column = box = split = _sub

    def label(self, text="", **kw):
        self.out.append(("label", text))

    def operator(self, idname, text="", **kw):
        self.out.append(("operator", idname, text))
        return type("Op", (), {})()

    def __getattr__(self, name):  # prop, prop_search, menu, separator, template_list ...
        return lambda *a, **kw: None


def draw(panel_cls, obj):
    out = []
    ctx = type("Ctx", (), {"object": obj, "scene": bpy.context.scene,
                           "region": None})()
    if panel_cls.poll(ctx):
        panel_cls.draw(type("P", (), {"layout": Rec(out)})(), ctx)
    else:
        out.append(("hidden",))
    return out


def ops(out):
    return {o[1] for o in out if o[0] == "operator"}


def text(out):
    return " ".join(o[1] for o in out if o[0] == "label")


def scene(method="ARAP"):
    S.reset_scene()
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(S.OUTPUT, "workflow.blend"))
    obj, d, e, fixed, handle = S.grid_setup(method)
    bpy.ops.deformkit.bind()
    return obj, d, e, handle


def lift(e, last, now):
    """Keys the empty from rest (frame 1) to 0.3 up (frame `last`), then goes to frame `now`."""
    e.location.z = 0.0
    e.keyframe_insert("location", frame=1)
    e.location.z = 0.3
    e.keyframe_insert("location", frame=last)
    bpy.context.scene.frame_set(now)


def test_point_cache_bake_shows_and_frees():
    obj, d, e, handle = scene()
    lift(e, 10, 5)
    out = draw(ui.DEFORMKIT_PT_modifiers, obj)
    R.check("animated, not baked: the panel warns", "frozen pose" in text(out), text(out))
    R.check("the cache file is a field next to Bake", d.bake_file == "" and
            "deformkit.bake" in ops(out))
    d.bake_file = "//workflow_cache.pc2"
    bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=10)
    st = bake.state(obj, d)
    R.check("the bake is recorded", st is not None and st["kind"] == "PC2" and
            (d.bake_start, d.bake_end) == (1, 10), st)
    out = draw(ui.DEFORMKIT_PT_modifiers, obj)
    R.check("baked: the panel names the cache and says edits don't show",
            "workflow_cache.pc2" in text(out) and "edits don't show" in text(out), text(out))
    R.check("baked: Free Bake and Re-bake offered, no animation warning",
            {"deformkit.free_bake", "deformkit.rebake"} <= ops(out)
            and "frozen pose" not in text(out), ops(out))
    R.check("the cache went to the panel's file",
            os.path.exists(bpy.path.abspath("//workflow_cache.pc2")))
    baked = S.evaluated_positions(obj)
    e.location.x += 0.4  # an edit while baked: invisible (the cache overwrites)
    bpy.context.view_layer.update()
    R.check("an edit does not show while baked",
            np.abs(S.evaluated_positions(obj) - baked).max() < 1e-6)
    bpy.ops.deformkit.free_bake()
    R.check("Free Bake removes the Mesh Cache and shows the deformer's modifier again",
            not [m for m in obj.modifiers if m.type == "MESH_CACHE"]
            and S.geonodes.find_modifier(obj, d).show_viewport and bake.state(obj, d) is None)
    bpy.context.view_layer.update()
    live = S.evaluated_positions(obj)
    R.check("after Free Bake the edit shows", np.abs(live - baked)[handle].max() > 0.1,
            np.abs(live - baked).max())
    e.location.x -= 0.4
    bpy.ops.deformkit.bake(mode="PC2", frame_start=2, frame_end=6)
    bpy.ops.deformkit.rebake()
    R.check("Re-bake keeps the kind and range",
            bake.state(obj, d)["kind"] == "PC2" and (d.bake_start, d.bake_end) == (2, 6)
            and len([m for m in obj.modifiers if m.type == "MESH_CACHE"]) == 1)


def test_a_bake_never_overwrites_what_it_was_not_asked_to():
    """Bake to Point Cache refuses any path that is not a point cache (the open .blend, a
    folder, a pipe or device, another object's cache, a missing folder) with an error naming it, before
    anything changes: the file, an earlier bake and the modifiers stay as they were, and no
    partial file is left. Baking again to its own cache replaces it."""
    obj, d, e, handle = scene()
    lift(e, 4, 3)
    blend = bpy.data.filepath
    folder = os.path.dirname(blend)
    body = open(blend, "rb").read()

    def leftovers():
        return [n for n in os.listdir(folder) if n.endswith(".part")]

    for n in leftovers():   # from an earlier run of a broken build: start clean
        os.remove(os.path.join(folder, n))
    shutil.rmtree(os.path.join(folder, "no_such_folder"), ignore_errors=True)

    def refused(path, words):
        d.bake_file = path
        try:
            bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=4)
            msg = None
        except RuntimeError as ex:
            msg = str(ex)
        R.check("a bake to %s is refused, saying %r" % (path, words),
                msg is not None and words in msg, msg)

    modifiers = [m.name for m in obj.modifiers]
    refused(blend, "the open .blend file")
    refused("//" + os.path.basename(blend), "the open .blend file")
    R.check("the .blend is untouched", open(blend, "rb").read() == body)
    refused("//", "is a folder")
    # a pipe stands for devices and sockets (never a real device: a wrong build would
    # replace it for the whole machine)
    fifo = os.path.join(folder, "workflow_fifo.pc2")
    if os.path.lexists(fifo):
        os.remove(fifo)
    os.mkfifo(fifo)
    refused(fifo, "not a regular file")
    R.check("the pipe is still a pipe", stat.S_ISFIFO(os.lstat(fifo).st_mode))
    os.remove(fifo)
    refused("//no_such_folder/x.pc2", "does not exist")
    R.check("no folder was made", not os.path.exists(os.path.join(folder, "no_such_folder")))
    notes = os.path.join(folder, "workflow_notes.txt")
    with open(notes, "w") as f:
        f.write("keep me")
    refused("//workflow_notes.txt", "not a point cache")
    R.check("a file that is not a cache is untouched", open(notes).read() == "keep me")
    # another object's Mesh Cache plays a cache: not this deformer's to replace
    other = S.make_grid(name="Other", nx=3, ny=3)
    theirs = os.path.join(folder, "workflow_theirs.pc2")
    S.addon.pc2.write(theirs, [[0.0] * 27], 9)
    their_bytes = open(theirs, "rb").read()
    mc = other.modifiers.new("Their Cache", "MESH_CACHE")
    mc.cache_format, mc.filepath = "PC2", "//workflow_theirs.pc2"
    bpy.context.view_layer.objects.active = obj
    refused("//workflow_theirs.pc2", "the cache that 'Other' plays")
    R.check("another object's cache is untouched", open(theirs, "rb").read() == their_bytes)
    R.check("nothing changed: no modifier added, no bake recorded, no partial file",
            [m.name for m in obj.modifiers] == modifiers and bake.state(obj, d) is None
            and leftovers() == [], ([m.name for m in obj.modifiers], leftovers()))
    # an earlier bake survives a refused one
    bpy.ops.deformkit.bake(mode="SHAPE_KEYS", frame_start=1, frame_end=4)
    refused(blend, "the open .blend file")
    R.check("a refused bake keeps the earlier shape-key bake",
            bake.state(obj, d) is not None and bake.state(obj, d)["kind"] == "SHAPE_KEYS")
    bpy.ops.deformkit.free_bake()
    # its own cache: baked, then baked again over it
    d.bake_file = "//workflow_own.pc2"
    bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=4)
    bpy.ops.deformkit.bake(mode="PC2", frame_start=2, frame_end=4)
    own = bpy.path.abspath("//workflow_own.pc2")
    R.check("baking again replaces its own cache",
            S.addon.pc2.read_header(own)["samples"] == 3 and leftovers() == [])


def test_groups_edited_by_a_script_are_seen_before_apply():
    """A vertex group removed or edited from a script (no update tells the add-on) after the
    bind: the deformer kept its stale groups and Apply wrote their result (the second
    hostile review). A removed group is now refused by name at the next solve and at Apply;
    edited contents are read again by Apply and by a bake's first frame. (Blender 3.4 tags no
    update at all for obj.vertex_groups.remove, where the old code failed here; 5.3 tags a
    geometry update, which re-read the groups already.)"""
    obj, d, e, handle = scene()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    fixed = obj.vertex_groups[d.fixed_group]
    members = [v.index for v in obj.data.vertices if any(g.group == fixed.index for g in v.groups)]
    want = S.dk.ARAP(S.dk.Mesh(S.rest_positions(obj), S.solver.triangles(obj.data)),
                     [handle], fixed=members[len(members) // 2:],
                     tolerance=d.options.tolerance, max_iterations=d.options.max_iterations)
    T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
    want = np.asarray(want.solve(transforms=T, warm_start=False).positions)
    base = S.rest_positions(obj)
    # contents edited, then Apply at once (no depsgraph evaluation between, as in a script):
    # the fixed group loses half its vertices
    fixed.remove(members[: len(members) // 2])
    bpy.ops.deformkit.apply(mode="SHAPE_KEY", keep=True)
    kb = obj.data.shape_keys.key_blocks[-1]
    co = np.empty(len(base) * 3, np.float32)
    kb.data.foreach_get("co", co)
    err = np.abs(co.reshape(-1, 3) - want).max()
    R.check("Apply reads the groups a script edited: the result of the current ones (%.1e)"
            % err, err < 1e-4, err)
    # removed: refused by name at Apply, the mesh untouched (a fresh scene: the shape key
    # edits above tag a geometry update, which re-reads the groups anyway)
    obj, d, e, handle = scene()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    base = S.rest_positions(obj)
    name = d.fixed_group
    obj.vertex_groups.remove(obj.vertex_groups[name])
    try:
        bpy.ops.deformkit.apply(mode="MESH")
        msg = None
    except RuntimeError as ex:
        msg = str(ex)
    R.check("Apply after a script removed the Fixed group: refused by name",
            msg is not None and "vertex group '%s' does not exist" % name in msg, msg)
    R.check("... the mesh untouched", np.array_equal(S.rest_positions(obj), base))
    e.location.z += 0.1
    bpy.context.view_layer.update()
    R.check("... and the next solve says so in the panel",
            d.status_is_error and "'%s' does not exist" % name in d.status, d.status)


def test_the_panel_says_when_a_method_cannot_do_the_edit():
    """Where a method cannot do an edit well, the panel says so and names the method that can
    (the second hostile review: Eigen Deformation's spike and the linear methods' swelling
    were shown as if fine): a Falloff drag that stretches edges by more than half, an Eigen
    Deformation fit whose handle is off its target; ARAP's result has nothing to say."""
    said = {}
    for mid in ("ARAP", "FALLOFF", "EIGEN"):
        S.reset_scene()
        obj, d, e, fixed, handle = S.grid_setup(mid, nx=24, ny=8)
        bpy.ops.deformkit.bind()
        e.location.z += 1.0
        bpy.context.view_layer.update()
        S.solver.finish(obj, d)
        said[mid] = text(draw(ui.DEFORMKIT_PT_modifiers, obj))
    R.check("ARAP: no warning about the fit", "ARAP keeps" not in said["ARAP"]
            and "meets its handles approximately" not in said["ARAP"], said["ARAP"])
    R.check("Falloff stretching edges: the panel says so and suggests ARAP",
            "by more than half" in said["FALLOFF"] and "ARAP keeps the shape" in said["FALLOFF"],
            said["FALLOFF"])
    R.check("Eigen Deformation off its handle: the panel says how far and suggests ARAP",
            "meets its handles approximately" in said["EIGEN"]
            and "ARAP meets them exactly" in said["EIGEN"], said["EIGEN"])


def test_shape_key_bake_shows_at_once_and_frees():
    obj, d, e, handle = scene()
    lift(e, 6, 4)
    want = S.evaluated_positions(obj)
    bpy.ops.deformkit.bake(mode="SHAPE_KEYS", frame_start=1, frame_end=6)
    S.handlers.enabled[0] = False  # what the keys alone show
    try:
        got = S.evaluated_positions(obj)
    finally:
        S.handlers.enabled[0] = True
    R.check("right after Bake to Shape Keys the mesh shows this frame's key (not the rest)",
            np.abs(got - want).max() < 1e-4, np.abs(got - want).max())
    R.check("shape key bake recorded", bake.state(obj, d)["kind"] == "SHAPE_KEYS")
    bpy.ops.deformkit.free_bake()
    keys = obj.data.shape_keys
    R.check("Free Bake removes the keys and the lone Basis", keys is None,
            keys and [k.name for k in keys.key_blocks])
    R.check("the live result shows again",
            S.geonodes.find_modifier(obj, d).show_viewport and bake.state(obj, d) is None)


def shown_by_the_bake(obj):
    """What the mesh shows with DeformKit's handlers off (the bake alone)."""
    S.handlers.enabled[0] = False
    try:
        return S.evaluated_positions(obj)
    finally:
        S.handlers.enabled[0] = True


def test_an_unwritten_bake_keeps_the_earlier_one():
    """A bake cancelled (Esc), failing or refused leaves the earlier bake as it was: its
    shape keys (set aside, muted, while the new bake ran), or its Mesh Cache; a written one
    replaces it."""
    from addon import bake
    obj, d, e, handle = scene()
    lift(e, 6, 4)
    bake.bake_shape_keys(bpy.context, obj, d, 1, 6)
    names = [k.name for k in obj.data.shape_keys.key_blocks]
    shown = shown_by_the_bake(obj)

    def keys_kept(what):
        keys = obj.data.shape_keys
        now = [] if keys is None else [k.name for k in keys.key_blocks]
        R.check("%s: the earlier shape keys stay, unmuted, and show" % what,
                now == names and not any(k.mute for k in keys.key_blocks) and
                bake.state(obj, d)["kind"] == "SHAPE_KEYS" and
                not S.geonodes.find_modifier(obj, d).show_viewport and
                np.abs(shown_by_the_bake(obj) - shown).max() < 1e-6, now)
    job = bake.ShapeKeyBake(bpy.context, obj, d, 1, 6)
    R.check("a bake under way mutes the earlier keys (they would move its input)",
            all(k.mute for k in obj.data.shape_keys.key_blocks if k.name != "Basis"))
    job.step()
    try:
        bake.PC2Bake(bpy.context, obj, d, 1, 6, os.path.join(S.OUTPUT, "workflow_two.pc2"))
        second = ""
    except S.solver.DeformKitError as ex:
        second = str(ex)
    R.check("a second bake of the deformer meanwhile is refused", "is being baked" in second,
            second)
    job.finish(False)
    keys_kept("a shape-key bake cancelled")
    job = bake.ShapeKeyBake(bpy.context, obj, d, 1, 6)
    name = obj.name
    obj.name = "Renamed meanwhile"
    try:
        job.step()
        stopped = False
    except S.solver.DeformKitError:
        stopped = True
    job.finish(False)
    obj.name = name
    R.check("the object renamed during a bake: the bake stops", stopped)
    keys_kept("the object renamed during a bake")
    path = os.path.join(S.OUTPUT, "workflow_aside.pc2")
    job = bake.PC2Bake(bpy.context, obj, d, 1, 6, path)
    job.step()
    job.finish(False)
    keys_kept("a point-cache bake cancelled")
    R.check("... and adds no Mesh Cache", obj.modifiers.get("%s Cache" % d.name) is None)
    for what, args in (("an empty range", (6, 1, path)), ("a folder", (1, 6, S.OUTPUT))):
        try:
            bake.bake_pc2(bpy.context, obj, d, *args, add_cache=True)
            refused = False
        except S.solver.DeformKitError:
            refused = True
        R.check("a point-cache bake refused for %s" % what, refused)
        keys_kept("a point-cache bake refused for %s" % what)
    bake.bake_pc2(bpy.context, obj, d, 1, 6, path, add_cache=True)
    mc = obj.modifiers.get("%s Cache" % d.name)
    R.check("a written point cache replaces the shape keys", obj.data.shape_keys is None and
            mc is not None and bake.state(obj, d)["kind"] == "PC2")
    cached = shown_by_the_bake(obj)
    job = bake.ShapeKeyBake(bpy.context, obj, d, 1, 6)
    job.step()
    job.finish(False)
    mc = obj.modifiers.get("%s Cache" % d.name)
    R.check("a shape-key bake cancelled keeps the point cache showing",
            mc is not None and mc.show_viewport and mc.show_render and
            not S.geonodes.find_modifier(obj, d).show_viewport and
            bake.state(obj, d)["kind"] == "PC2" and obj.data.shape_keys is None and
            np.abs(shown_by_the_bake(obj) - cached).max() < 1e-6)
    obj.shape_key_add(name="Basis", from_mix=False)
    obj.shape_key_add(name="Key 1", from_mix=False)
    obj.data.shape_keys.use_relative = False
    try:
        bake.ShapeKeyBake(bpy.context, obj, d, 1, 6)
        msg = ""
    except S.solver.DeformKitError as ex:
        msg = str(ex)
    R.check("Bake to Shape Keys refused over absolute shape keys", "absolute" in msg and
            [k.name for k in obj.data.shape_keys.key_blocks] == ["Basis", "Key 1"], msg)
    obj.shape_key_clear()


def test_shape_key_bake_over_other_shape_keys():
    """Shape keys of the artist's above the deformer add up with the baked ones on
    playback: each baked key holds the deformer's offset on the Basis, and the keys together
    show what the modifier showed (a key holding the shown mix counted the others twice)."""
    from addon import bake
    for method in ("ARAP", "LINEAR_RECONSTRUCTION"):
        obj, d, e, handle = scene(method)
        obj.shape_key_add(name="Basis", from_mix=False)
        bulge = obj.shape_key_add(name="Bulge", from_mix=False)
        co = np.empty(3 * len(obj.data.vertices))
        bulge.data.foreach_get("co", co)
        co = co.reshape(-1, 3)
        co[:, 2] += 0.05 * np.sin(3.0 * co[:, 0])
        bulge.data.foreach_set("co", co.ravel())
        for f, v in ((1, 0.0), (6, 1.0)):
            bulge.value = v
            bulge.keyframe_insert("value", frame=f)
        lift(e, 6, 1)
        want = {}
        for f in (3, 5):
            bpy.context.scene.frame_set(f)
            want[f] = S.evaluated_positions(obj)
        bake.bake_shape_keys(bpy.context, obj, d, 1, 6)
        for f in (3, 5):
            bpy.context.scene.frame_set(f)
            err = np.abs(shown_by_the_bake(obj) - want[f]).max()
            R.check("%s: the baked keys with the artist's show frame %d as played"
                    % (method, f), err < 1e-4 and np.abs(want[f] - want[3 if f == 5 else 5])
                    .max() > 1e-2, err)


def test_sidebar_and_handle_target():
    obj, d, e, handle = scene()
    out = draw(ui.DEFORMKIT_PT_sidebar, obj)
    R.check("sidebar: the mesh's deformer with Bind", "deformkit.bind" in ops(out)
            and d.name in text(out), out)
    out = draw(ui.DEFORMKIT_PT_sidebar, e)
    R.check("sidebar with the handle's empty selected: what it moves, with Bind",
            "deformkit.bind" in ops(out) and "Tip moves" in text(out) and "Grid" in text(out),
            out)
    out = draw(ui.DEFORMKIT_PT_handle_target, e)
    R.check("the empty's Object tab says what it moves", "moves handle 'tip' of Grid"
            in text(out), out)
    R.check("no handle line on an unrelated empty",
            draw(ui.DEFORMKIT_PT_handle_target, S.empty("Other")) == [("hidden",)])
    plain = S.make_grid("Plain")
    R.check("no DeformKit panel on a mesh without a deformer",
            draw(ui.DEFORMKIT_PT_modifiers, plain) == [("hidden",)])
    out = []
    ctx = type("Ctx", (), {"object": e})()
    ui._draw_object_menu(type("M", (), {"layout": Rec(out)})(), ctx)
    R.check("no deformer entry in the Object menu for an empty", out == [], out)


def test_errors_with_a_way_out():
    obj, d, e, handle = scene()
    S.group(obj, "fixed", [int(handle[0]), int(handle[1])])  # now overlaps the handle
    bpy.context.view_layer.update()
    S.addon.solver.evaluate_object(obj, bpy.context.evaluated_depsgraph_get(),
                                   check_groups=True)
    R.check("overlap error records its groups", d.status_is_error and
            d.status_overlap == "tip\tfixed", (d.status, d.status_overlap))
    out = draw(ui.DEFORMKIT_PT_modifiers, obj)
    R.check("overlap: Select Shared and Remove offered", "deformkit.overlap" in ops(out)
            and "Remove from 'fixed'" in [o[2] for o in out if o[0] == "operator"], out)
    bpy.ops.deformkit.overlap(action="SELECT", group="tip", other="fixed")
    R.check("Select Shared: Edit Mode with the shared vertices", obj.mode == "EDIT")
    bpy.ops.object.mode_set(mode="OBJECT")
    sel = [v.index for v in obj.data.vertices if v.select]
    R.check("exactly the shared vertices selected", sorted(sel) == sorted(handle[:2].tolist()),
            sel)
    bpy.ops.deformkit.overlap(action="REMOVE", group="fixed", other="tip")
    bpy.ops.deformkit.bind()
    R.check("after Remove from 'fixed' the bind works", d.bound and not d.status_is_error,
            d.status)
    # a deleted modifier: Restore Modifier, the deformer and its handles kept
    obj.modifiers.remove(S.geonodes.find_modifier(obj, d))
    out = draw(ui.DEFORMKIT_PT_modifiers, obj)
    R.check("a removed modifier offers Restore Modifier",
            "deformkit.restore_modifier" in ops(out))
    bpy.ops.deformkit.restore_modifier()
    R.check("Restore Modifier: the modifier is back, the handles kept",
            S.geonodes.find_modifier(obj, d) is not None and len(d.handles) == 1)
    e.location.z += 0.2
    bpy.context.view_layer.update()
    R.check("the restored modifier shows the result",
            np.abs(S.evaluated_positions(obj) - S.rest_positions(obj))[handle].max() > 0.1)
    # the Attribute input edited by hand: found by the modifier's name, repaired
    mod = S.geonodes.find_modifier(obj, d)
    S.compat.set_modifier_input(mod, S.geonodes.attribute_key(mod.node_group), "typo")
    R.check("an edited Attribute input: the modifier is still found",
            S.geonodes.find_modifier(obj, d) == mod)
    e.location.z += 0.1
    bpy.context.view_layer.update()
    R.check("and repaired by the next update",
            S.compat.modifier_input(mod, S.geonodes.attribute_key(mod.node_group))
            == d.attribute_name)
    if hasattr(S.geonodes.compat.group_sockets(mod.node_group)[0], "hide_in_modifier"):
        hidden = {s.name for s in S.geonodes.compat.group_sockets(mod.node_group)
                  if getattr(s, "hide_in_modifier", False)}
        R.check("the modifier's plumbing inputs are hidden from its panel",
                hidden == {"Factor", "Attribute", "Input"}, hidden)
    # Bind with the modifier off everywhere: a warning, not a plain success
    mod.show_viewport = mod.show_render = False
    bpy.ops.deformkit.bind()
    out = draw(ui.DEFORMKIT_PT_modifiers, obj)
    R.check("a modifier that is off: the panel says nothing shows",
            "nothing shows the result" in text(out), text(out))


def test_keyed_factor_warns():
    obj, d, e, handle = scene()
    mod = S.geonodes.find_modifier(obj, d)
    obj.keyframe_insert(S.geonodes.factor_data_path(mod), frame=1)
    R.check("a keyed Factor: animated", bake.animated_reason(obj, d) == "its Factor is keyed",
            bake.animated_reason(obj, d))


def test_factor_writes_and_edits_re_evaluate():
    """The Factor written from the add-on's code re-evaluates the object in every Blender; an
    edit in the panel too: in 5.2 such an edit re-evaluates nothing by itself, so a message-bus
    subscription per node group (geonodes.watch_factor_edits) tags the objects. Blender as a
    module runs no event loop, so the subscription's callback is called here directly."""
    obj, d, e, handle = scene()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    rest = S.rest_positions(obj)
    full = S.evaluated_positions(obj)
    mod = S.geonodes.find_modifier(obj, d)
    S.geonodes.set_factor(mod, 0.5)
    R.check("set_factor(0.5): the object shows half the offset at once",
            np.abs(S.evaluated_positions(obj) - (rest + 0.5 * (full - rest))).max() < 1e-5)
    watched = S.geonodes.watch_factor_edits()
    R.check("one node group watched for Factor edits where inputs are RNA (5.2+), none before",
            watched == (1 if S.compat.MODIFIER_INPUTS_RNA else 0), watched)
    owner, prop = S.geonodes.factor_prop(mod)
    setattr(owner, prop, 0.25)   # what the panel's slider does
    S.geonodes._factor_edited()
    R.check("a Factor edited in the panel: the object shows it",
            np.abs(S.evaluated_positions(obj) - (rest + 0.25 * (full - rest))).max() < 1e-5)
    S.geonodes.set_factor(mod, 1.0)


def test_falloff_reach_scales_with_the_model():
    """The automatic range: each handle's distance to the Fixed group (the native
    reach='fixed'), so a model 10x larger deforms the same way relative to its size; without
    a Fixed group a quarter of the diagonal. A Range typed in is used as given."""
    shapes = []
    for scale in (1.0, 10.0):
        obj, d, e, handle = scene("FALLOFF")
        obj.data.transform(Matrix.Scale(scale, 4))
        e.location = (1.0 * scale, 0.0, 0.0)
        bpy.ops.deformkit.bind()
        native = S.addon.solver.cache._cache[(obj.name, d.uid)].native
        rest = S.rest_positions(obj)
        fixed = np.array([i for i, v in enumerate(obj.data.vertices)
                          if any(g.group == obj.vertex_groups["fixed"].index
                                 for g in v.groups)])
        near = np.linalg.norm(rest[handle][:, None] - rest[fixed][None], axis=2).min()
        R.check("scale %g: the range is the handle's distance to the Fixed group" % scale,
                abs(float(np.asarray(native.ranges)[0]) - near) < 1e-6 * near,
                (np.asarray(native.ranges), near))
        e.location.z += 0.3 * scale
        bpy.context.view_layer.update()
        shapes.append((S.evaluated_positions(obj) - rest) / scale)
    R.check("a 10x larger model deforms the same relative to its size",
            np.abs(shapes[0] - shapes[1]).max() < 1e-5, np.abs(shapes[0] - shapes[1]).max())
    d.fixed_group = ""
    bpy.ops.deformkit.bind()
    native = S.addon.solver.cache._cache[(obj.name, d.uid)].native
    diag = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    R.check("without Fixed: a quarter of the diagonal",
            abs(float(np.asarray(native.ranges)[0]) - 0.25 * diag) < 1e-6 * diag)
    d.options.range_length = 0.123
    bpy.ops.deformkit.bind()
    native = S.addon.solver.cache._cache[(obj.name, d.uid)].native
    R.check("a Range typed in is used", abs(float(np.asarray(native.ranges)[0]) - 0.123) < 1e-6)


def shown_meanwhile_then_installed(obj, before):
    """While a background re-bind of obj's deformer runs: the last result stays shown and
    the panel says so; then waits for it (the poll timer's work) and returns what shows."""
    import time
    solver = S.addon.solver
    R.check("meanwhile the last result stays shown",
            np.abs(S.evaluated_positions(obj) - before).max() < 1e-6)
    out = draw(ui.DEFORMKIT_PT_modifiers, obj)
    R.check("the panel says it is re-binding", "re-binding" in text(out), text(out))
    t0 = time.time()
    while solver.rebinding() and time.time() - t0 < 30:
        time.sleep(0.01)
        S.handlers.poll_rebinds()
    bpy.context.view_layer.update()
    return S.evaluated_positions(obj)


def test_option_change_rebinds_in_a_thread():
    """In the UI an option or method change re-binds in a worker thread (it froze the
    handler for 0.4-0.75 s at 43k): the last result stays shown and the panel says
    "re-binding"; when the thread is done the next update shows exactly what a synchronous
    re-bind gives. (Forced here: blender -b re-binds synchronously.)"""
    import time
    obj, d, e, handle = scene()
    e.location.z += 0.3
    bpy.context.view_layer.update()
    before = S.evaluated_positions(obj)
    solver = S.addon.solver
    solver.threaded_rebinds[0] = True
    try:
        d.method = "LAPLACIAN"
        bpy.context.view_layer.update()
        R.check("a method change starts a background re-bind",
                solver.rebinding(obj, d) is not None)
        threaded = shown_meanwhile_then_installed(obj, before)
    finally:
        solver.threaded_rebinds[0] = None
    R.check("the re-bind finished and is installed", not solver.rebinding() and
            not d.status_is_error, d.status)
    solver.drop(obj.name, d.uid)  # the same change, bound synchronously
    solver.threaded_rebinds[0] = False
    try:
        e.location.x += 1e-3
        bpy.context.view_layer.update()
        e.location.x -= 1e-3
        bpy.context.view_layer.update()
    finally:
        solver.threaded_rebinds[0] = None
    sync = S.evaluated_positions(obj)
    R.check("then it shows what a synchronous re-bind gives",
            np.abs(threaded - sync).max() < 1e-6 and np.abs(threaded - before).max() > 1e-4,
            (np.abs(threaded - sync).max(), np.abs(threaded - before).max()))


def test_group_change_rebinds_in_place_in_a_thread():
    """A vertex group's membership change on a big mesh re-binds the bound object in place
    (its native rebind) in a worker thread in the UI, with the native progress in the panel:
    at 692k vertices it re-factors for seconds and froze the handler. Meanwhile the last
    result stays shown; a frame's solve waits for it; then the result is the one a
    synchronous re-bind gives. (Forced here: a small mesh and blender -b re-bind
    synchronously.)"""
    import time
    obj, d, e, handle = scene("LAPLACIAN")
    e.location.z += 0.3
    bpy.context.view_layer.update()
    before = S.evaluated_positions(obj)
    solver = S.addon.solver
    key = (obj.name, d.uid)
    native = solver.cache._cache[key].native
    vg = obj.vertex_groups["fixed"]
    members = [v.index for v in obj.data.vertices if any(g.group == vg.index for g in v.groups)]
    threshold = solver.REBIND_ASYNC_MIN_VERTICES[0]
    solver.threaded_rebinds[0] = True
    solver.REBIND_ASYNC_MIN_VERTICES[0] = 0
    try:
        vg.remove(members[1::2])
        obj.data.update()
        bpy.context.view_layer.update()
        R.check("a group change starts an in-place re-bind in a thread",
                solver.rebind._in_place_rebind(key) is not None)
        threaded = shown_meanwhile_then_installed(obj, before)
        R.check("the same native object, re-bound", solver.cache._cache[key].native is native and
                not d.status_is_error, d.status)
        # again, and a frame's (non-interactive) solve right away: it waits for the worker
        vg.remove(members[0:4:2])
        obj.data.update()
        bpy.context.view_layer.update()
        R.check("a second group change re-binds in a thread too",
                solver.rebind._in_place_rebind(key) is not None)
        got = solver.solve(obj, d, force=True)
        R.check("a frame's solve waits for it and installs it",
                solver.rebind._in_place_rebind(key) is None and got is not None)
    finally:
        solver.threaded_rebinds[0] = None
        solver.REBIND_ASYNC_MIN_VERTICES[0] = threshold
    solver.drop(obj.name, d.uid)  # the same groups, bound synchronously
    solver.threaded_rebinds[0] = False
    try:
        vg.add(members[0:4:2], 1.0, "REPLACE")
        obj.data.update()
        bpy.context.view_layer.update()
        sync_first = S.evaluated_positions(obj)
        vg.remove(members[0:4:2])
        obj.data.update()
        bpy.context.view_layer.update()
    finally:
        solver.threaded_rebinds[0] = None
    sync = S.evaluated_positions(obj)
    R.check("the threaded re-bind showed what a synchronous one gives",
            np.abs(threaded - sync_first).max() < 1e-6 and
            np.abs(threaded - before).max() > 1e-4,
            (np.abs(threaded - sync_first).max(), np.abs(threaded - before).max()))
    R.check("and the frame's solve too", np.abs(np.asarray(got) - sync).max() < 1e-6,
            np.abs(np.asarray(got) - sync).max())


def test_modal_bake_frames_solve_in_a_worker_thread():
    """The modal bake solves each frame in a worker thread (solver.FrameSolve), an iterative
    method in resumed slices (so that Esc stops a big mesh's frame within about a slice):
    the cache is the one the synchronous bake writes; a bake stopped while a frame solves
    leaves the object solving as before."""
    from addon import bake, pc2
    obj, d, e, handle = scene("ARAP")
    e.location.z = 0.0
    e.keyframe_insert("location", frame=1)
    e.location.z = 0.6
    e.location.x = 0.4
    e.keyframe_insert("location", frame=6)
    bpy.context.scene.frame_set(1)
    sync_path = os.path.join(S.OUTPUT, "sync.pc2")
    async_path = os.path.join(S.OUTPUT, "async.pc2")
    bake.bake_pc2(bpy.context, obj, d, 1, 6, sync_path)
    solver = S.addon.solver
    slice_ms, quick = solver.workers.BAKE_SLICE_MS, bake.QUICK_FRAME_S
    solver.workers.BAKE_SLICE_MS = 1e-6  # one iteration a slice: the most resumed slices
    bake.QUICK_FRAME_S = 0.0  # a tick does not wait for the frame it starts
    # each frame's first slice waits until the main thread has ticked once while it is
    # pending (a busy machine may otherwise let the worker finish between two ticks): the
    # ticks between are then certain, and the slices' threads and resumptions are counted
    import threading
    calls, native_call = solver.workers.calls, solver.workers.calls._native_call
    ticked, slices = threading.Event(), []

    def gated(what, fn, *a, **kw):
        worker = threading.current_thread() is not threading.main_thread()
        slices.append((worker, bool(kw.get("resume"))))
        if worker and not kw.get("resume"):
            ticked.wait(60)
            ticked.clear()
        return native_call(what, fn, *a, **kw)
    calls._native_call = gated
    try:
        job = bake.PC2Bake(bpy.context, obj, d, 1, 6, async_path)
        ticks, busy_ticks = 0, 0
        while not job.done:
            f = job.step_async()
            if f is None and job.fb.solving() is not None:
                busy_ticks += 1
                ticked.set()
            ticks += 1
        job.finish(True)
    finally:
        calls._native_call = native_call
        solver.workers.BAKE_SLICE_MS, bake.QUICK_FRAME_S = slice_ms, quick
    a = np.array([np.asarray(x) for x in pc2.read(sync_path)[1]])
    b = np.array([np.asarray(x) for x in pc2.read(async_path)[1]])
    R.check("the modal bake's frames were solved in a worker (ticks between)",
            busy_ticks >= 6 and ticks >= 12 and slices and all(w for w, _ in slices),
            (ticks, busy_ticks, len(slices)))
    R.check("in resumed slices", sum(r for _, r in slices) >= 6,
            sum(r for _, r in slices))
    R.check("its cache equals the synchronous bake's", a.shape == b.shape and
            np.abs(np.asarray(a) - np.asarray(b)).max() < 1e-6,
            (a.shape, b.shape, np.abs(np.asarray(a) - np.asarray(b)).max()))
    # stopped while a frame solves (Esc): the worker's slices stop, the object stays usable
    job = bake.PC2Bake(bpy.context, obj, d, 1, 6, async_path)
    try:
        job.fb.step_begin()
        pending = job.fb.pending[1]
    finally:
        job.finish(False)
    pending.thread.join(30)
    R.check("a stopped bake's frame solve ends", not pending.thread.is_alive())
    R.check("and leaves no file", not os.path.exists(async_path + ".part"))
    bpy.context.scene.frame_set(6)
    got = np.asarray(solver.deformed_positions(obj, d))
    R.check("then frames solve as before", np.abs(got.ravel() - a[-1]).max() < 1e-5,
            np.abs(got.ravel() - a[-1]).max())


for t in (test_an_unwritten_bake_keeps_the_earlier_one, test_shape_key_bake_over_other_shape_keys, test_the_panel_says_when_a_method_cannot_do_the_edit, test_groups_edited_by_a_script_are_seen_before_apply, test_a_bake_never_overwrites_what_it_was_not_asked_to, test_factor_writes_and_edits_re_evaluate, test_option_change_rebinds_in_a_thread, test_modal_bake_frames_solve_in_a_worker_thread, test_group_change_rebinds_in_place_in_a_thread, test_falloff_reach_scales_with_the_model, test_point_cache_bake_shows_and_frees, test_shape_key_bake_shows_at_once_and_frees,
          test_sidebar_and_handle_target, test_errors_with_a_way_out, test_keyed_factor_warns):
    R.run(t)
R.finish()

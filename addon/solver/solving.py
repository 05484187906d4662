"""Solving a bound deformer for the targets' current placement on this frame: what to ask the
native object (the handles' transforms, the animated input), and what reaches the modifier."""

import hashlib
import math
import struct
import time

import bpy
import numpy as np

from .. import geonodes, methods, native
from ..animated_input import depends_on_input, edit_targets, input_transforms, moved_input
from ..errors import DeformKitError
from ..handles import transforms, turn_with_the_pose
from . import (binding, blender_data, budget, cache, calls, controls, identity, material,
               previews, rebind, simulation, status, workers)


def solve(obj, d, depsgraph=None, cold=False, write=True, force=False, check_groups=False,
          interactive=False, resume=False, check_topology=None, defer=False):
    """Solves `d` for the targets' current placement. Returns the n x 3 positions, or None when
    nothing changed since the last solve (unless `force`). Raises DeformKitError.
    `interactive` (UI updates): an iterative method stops at the time budget and is marked
    pending; the timer in handlers.py continues it (`resume`: from where it stopped, as one
    long solve would) with further interactive solves. A slow interactive solve runs in a
    worker thread (_async_wanted): the call returns None at once, and a later call (the
    refine timer's) installs its result. `defer` (non-interactive solves: bakes): the native
    solve starts in a worker thread and a FrameSolve is returned instead of positions."""
    if not d.bound:
        raise DeformKitError("not bound: press Bind")
    blender_data.check_object(obj, d)
    identity.ensure_own_uid(obj, d)
    key = (obj.name, d.uid)
    r = rebind._in_place_rebind(key)
    if r is not None:  # a groups re-bind has the native object (GroupsRebindJob)
        if interactive and not cold:
            raise rebind.RebindPending()
        r["thread"].join()  # a frame, bake or Apply: its result must be this frame's
        rebind.finish_rebinds()
    ce = cache._cache.get(key)
    if ce is not None and ce.worker is not None and ce.worker.thread.is_alive():
        if interactive and write and not cold and not check_groups:
            ce.pending = True  # the timer polls it
            T, _, inputs = _solve_inputs(obj, d, ce, depsgraph)
            return previews._basis_preview(obj, d, ce, T, inputs)
        workers._wait_for_worker(key)
    # the topology in full (check_topology) for Apply, bakes, scripts and blender -b (None:
    # all but interactive solves); the UI's handler asks for it after a geometry update the
    # add-on did not make, an Edit or Sculpt Mode session or an undo (handlers._run)
    full = (not interactive) if check_topology is None else check_topology
    e = binding._entry_for(obj, d, check_groups,
                           threaded=not cold and rebind._use_threads(interactive),
                           full_check=full)
    w, e.worker = e.worker, None
    if isinstance(w, workers.FrameSolve):
        w = None  # a bake's frame (finished): its owner takes the result (FrameSolve.result)
    shown = None
    T, source, inputs = _solve_inputs(obj, d, e, depsgraph)
    m = methods.get(d.method)
    dynamic = simulation.is_dynamic(m)
    if dynamic:  # a simulation: the frame, and the keyed settings, are inputs
        scene = bpy.context.scene
        inputs += _frame_inputs(m, d, obj, scene)
    elif m.solve_args is not None:  # keywords read from the scene (a blend's weights)
        inputs += repr(sorted(m.solve_args(obj, d.options, bpy.context.scene).items())).encode()
    if w is not None:  # a worker's solve ended: its result shows now (if still wanted)
        if w.error is not None:
            e.pending = False
            raise w.error
        if interactive and write and not cold:
            plan_w = w.plan
            if inputs != w.plan["inputs"] and previews._has_basis(e):
                # the handles moved on: the preview from this result is what shows (below)
                plan_w = dict(w.plan, write=False)
            shown = _finish_solve(obj, d, e, key, plan_w, w.result, w.ms)
    if shown is not None and inputs == w.plan["inputs"]:
        return shown  # the worker's result is for the targets as they are
    if write:
        # Show Material follows its checkbox at once, not at the next solve (it showed
        # nothing until the handle moved, and stayed after unticking: the second hostile
        # review); show_material writes only on a change
        material.show_material(obj, d, e)
    # unchanged inputs keep the shown result, except that a frame (cold) must show what a bake
    # of it writes: a cold solve's result, not a drag's warm, budgeted or preview one (the
    # second hostile review: ARAP 2.6e-5 of the diagonal off, EmbeddedDeformation 1e-3,
    # EigenDeformation its Steps 1-2 preview)
    if not force and e.last_inputs == inputs and (e.last_cold or not cold):
        return shown
    plan = _plan_solve(obj, d, e, key, T, source, inputs, cold, write, interactive,
                       resume and shown is None)
    if dynamic:  # this frame from the one before it, or kept (milliseconds: no worker)
        t0 = time.perf_counter()
        res = simulation.solve(e, plan, calls._native_call, scene.frame_current,
                               scene.frame_start, lambda k: _stored_frame(obj, d, e, k))
        ms = (time.perf_counter() - t0) * 1000.0
        plan["sim_key"] = _sim_key(e, e.sim.shown) if e.sim.shown is not None else ""
        return _finish_solve(obj, d, e, key, plan, res, ms)
    if workers._async_wanted(e, interactive, cold, write):
        previews._fetch_basis(e, methods.get(d.method))  # the object is idle now
        e.worker = workers._Worker(e, plan)
        e.pending = True
        preview = previews._basis_preview(obj, d, e, T, inputs)
        return shown if preview is None else preview
    if defer:
        job = workers.FrameSolve(key, e, plan, methods.get(d.method).iterative)
        e.worker = job
        return job
    t0 = time.perf_counter()
    res = calls._native_call(plan["label"] + " solve", e.native.solve, **plan["goal"], **plan["kw"])
    ms = (time.perf_counter() - t0) * 1000.0
    return _finish_solve(obj, d, e, key, plan, res, ms)


def _sim_key(e, frame_key):
    """What d.sim_frame_key holds for a simulated frame: its frame key (simulation.frame_key:
    the frame, its input, handles and solve settings) and the binding's own (the method, the
    bind settings, the groups and paints, the rest shape): a re-bind with other settings is
    another simulation. Hex; the same after a reload."""
    sim = e.sim
    if sim.rest_of is not e.rest:   # the rest shape's digest, once per binding
        sim.rest_of = e.rest
        sim.rest_digest = hashlib.blake2b(np.ascontiguousarray(e.rest).tobytes(),
                                          digest_size=20).digest()
    h = hashlib.blake2b(frame_key, digest_size=20)
    h.update(str(e.method_id).encode())
    h.update(repr(e.settings).encode())
    h.update(e.groups if isinstance(e.groups, bytes) else repr(e.groups).encode())
    h.update(sim.rest_digest)
    return h.hexdigest()


def _stored_frame(obj, d, e, frame_key):
    """The positions the deformer's offset attribute holds when they are a simulation's
    frame `frame_key` of this binding (d.sim_frame_key says which frame the attribute holds:
    _sim_key), else None."""
    if not d.sim_frame_key or d.sim_frame_key != _sim_key(e, frame_key):
        return None
    me = obj.data
    a = me.attributes.get(d.attribute_name)
    if a is None or len(a.data) != len(me.vertices) or e.source is None:
        return None
    off = np.empty(len(me.vertices) * 3, dtype=np.float32)
    a.data.foreach_get("vector", off)
    return e.source + off.reshape(-1, 3).astype(np.float64)


def _frame_inputs(m, d, obj, scene):
    """What a simulation's frame depends on besides the handles and the input (bytes): the
    frame, the first frame, and this frame's keyed options and scene settings (gravity, the
    frame's length)."""
    kw = methods.solve_kwargs(m, d.options, True)
    if m.solve_args is not None:
        kw.update(m.solve_args(obj, d.options, scene))
    return struct.pack("<qq", scene.frame_current, scene.frame_start) + \
        repr(sorted(kw.items())).encode()


def _input_or_none(obj, d, depsgraph):
    """The deformer's input for a method that solves from the rest (where its handles' edits
    turn with the pose), or None when it is the rest, or cannot be read (a modifier below
    changes the vertex count): the edits then keep their direction, as they did."""
    try:
        return moved_input(obj, d, depsgraph)
    except DeformKitError:
        return None


def _solve_inputs(obj, d, e, depsgraph):
    """The handle transforms, the animated input (methods that follow one, else None) and
    the bytes they make, which say whether anything changed since the last solve."""
    m = methods.get(d.method)
    source = moved_input(obj, d, depsgraph) if depends_on_input(m, d) else None
    c = controls.collector(m)
    if not c.uses_handles:
        # a control object: its points on this frame are the targets (T holds them)
        P = c.targets(obj, d, e, depsgraph)
        return P, source, P.tobytes() + (b"" if source is None else source.tobytes())
    inp = source if depends_on_input(m, d) else _input_or_none(obj, d, depsgraph)
    T = budget.snap_identity(turn_with_the_pose(d, e.rest, e.handles,
                                                transforms(obj, d, depsgraph), inp), e.extent)
    last = e.last_T
    # (not for a simulation: a frame's input must not depend on the frame shown before it)
    if last is not None and last.shape == T.shape and budget._within_rounding(T, last, e.extent) \
            and not simulation.is_dynamic(m):
        # the same placement seen through other float32 products (the object and its
        # child target moved together): the last solve's, so that nothing is solved again
        # (a warm iterative solve from its own result moves it by up to its tolerance)
        T = last
    if len(T) > len(e.handles):  # region_is_handle: the Region group moves with the first
        T = T[:len(e.handles)]
    return T, source, T.tobytes() + (b"" if source is None else source.tobytes())


def _plan_solve(obj, d, e, key, T, source, inputs, cold, write, interactive, resume):
    """What a solve of `d` asks the native object for now: the goal (targets), the solve
    keywords (the budget's slice when interactive) and the inputs they come from."""
    m = methods.get(d.method)
    goal = dict(transforms=T)
    kw = methods.solve_kwargs(m, d.options, cold)
    if m.solve_args is not None:  # from the scene (a simulation's gravity and frame length)
        kw.update(m.solve_args(obj, d.options, bpy.context.scene))
    if not controls.collector(m).uses_handles:
        # a control object's points (_solve_inputs); a method that edits its input
        # registers the input to the control where it lies, the others solve on the rest
        # and their offset lands on the input
        goal = {controls.collector(m).SOLVE_KEYWORD: T}
        if source is not None:
            kw["input_positions"] = source
        e.source = e.rest if source is None else source
    elif depends_on_input(m, d):
        want = e.rest if source is None else source
        from_rest = d.solve_from == "REST" and m.needs_handles  # (else not drawn)
        if source is not None and not from_rest and m.poses is not None:
            # a blend of poses edits the input less the linear blend it replaces: its handles
            # too are placed on that (kw["input_positions"] below)
            source = methods.poses_reader(m).edit_input(obj, d.options, source, e.pose_deltas)
        solve_on = e.rest if from_rest else want   # what the native object deforms
        ns = getattr(e, "native_source", None)
        if m.follows_input and (ns is None or not np.array_equal(ns, solve_on)):
            calls._native_call(m.label + " input", e.native.update_source, solve_on)
            e.native_source = solve_on
        e.source = want   # the offset written is the result less the input
        if source is not None and from_rest:
            # Solve From: Rest Shape: the handles where the input puts them (plus the
            # edit), the rest between them solved from the rest shape
            goal = dict(targets=edit_targets(e, T, source))
        elif source is not None:
            # the edit where the input puts the handle vertices: positions where they are
            # the transforms' equal, else transforms turned into the input
            positions = m.follows_input or native.method_info(m.native_class).get(
                "transforms_as_positions", False)
            goal = (dict(targets=edit_targets(e, T, source)) if positions
                    else dict(transforms=input_transforms(e, T, source)))
            if not m.follows_input:
                kw["input_positions"] = source
    else:
        e.source = e.rest   # solved on the rest, its offset lands on the input as it is
    # after an undo or redo: a full solve before showing (mark_all_dirty)
    full = write and cache.converges_next(key)
    budgeted = interactive and m.iterative and not cold and not full
    previewing = interactive and bool(m.preview) and not cold and not resume and not full
    if previewing:
        kw.update(m.preview)
    cap = int(getattr(d.options, m.iteration_cap)) if m.iteration_cap else 0
    n_inner = budget.inner_cap(m, d.options) if budgeted else 0
    inner = None
    if budgeted:
        # slices of one solve: together at most the method's Max Iterations (counted in full
        # iterations: a Newton step of 3 CG iterations out of 12 is a quarter). A slice of
        # whole iterations resumed by another of whole iterations is exactly what one
        # uninterrupted solve would give; slices cut to fewer inner iterations take another
        # path to a point the same stopping test accepts (docs/methods/arap.md)
        now = time.monotonic()
        if not resume:
            e.pending_its, e.moved_at = 0, now
        its, inner = budget._budget(key, cap or 100, n_inner, resume,
                                    cut=not resume or now - e.moved_at < budget.PREVIEW_SETTLE_S)
        left = cap - e.pending_its if cap else 1 << 30
        kw["max_iterations"] = max(1, min(its, int(math.ceil(left))))
        if inner is not None:
            kw[m.inner_iterations] = inner
        if resume:
            kw["resume"] = True
    return dict(label=m.label, goal=goal, kw=kw, inputs=inputs, T=T, budgeted=budgeted,
                previewing=previewing, resume=resume, cap=cap, n_inner=n_inner, inner=inner,
                write=write, cold=cold)


def _finish_solve(obj, d, e, key, plan, res, ms):
    """Records a native solve's figures and pending state, and writes its result (when the
    plan says so). Returns the n x 3 positions."""
    budgeted, resume, inner = plan["budgeted"], plan["resume"], plan["inner"]
    cap, n_inner = plan["cap"], plan["n_inner"]
    e.slice_ms = ms
    pos = np.asarray(res.positions, dtype=np.float64).reshape(-1, 3)
    # the base of the response-basis previews (_basis_preview): the object's own last result
    Tg = plan["goal"].get("transforms")
    e.result_pos = pos if Tg is not None else None
    e.result_T = None if Tg is None else np.asarray(Tg, dtype=np.float64)
    # inner: the inner count of a slice's iterations when cut below the bound one (ARAP: CG
    # iterations per Newton step), else None
    rt = dict(ms=ms, iterations=int(res.iterations), converged=bool(res.converged),
              energy=float(res.energy), slices=1, inner=inner, budgeted=budgeted)
    last = cache.runtime.get(key)
    if budgeted and resume and e.pending and last is not None:
        # a further slice of the interactive solve left pending: the figures are the whole
        # solve's (its time and iterations so far), not this slice's
        rt["ms"] += last["ms"]
        rt["iterations"] += last["iterations"]
        rt["slices"] += last["slices"]
    cache.runtime[key] = rt
    # unconverged only because of the budget: finish from the timer
    if budgeted:
        per_it = inner if inner is not None else (n_inner or 1)
        e.pending_its += int(res.iterations) * per_it / (n_inner or 1)
        if not (n_inner and res.converged):
            # (a converged Newton slice ended at its stopping test, one product into a step:
            # its time says nothing of a full unit's)
            e.slice_cost[bool(resume)] = (ms, max(int(res.iterations), 1), per_it)
    e.pending = bool(budgeted and not res.converged and (not cap or e.pending_its < cap))
    if plan["previewing"]:  # the full result follows from the timer once the handles stop
        e.pending, e.preview_at = True, time.monotonic()
    else:
        e.preview_at = 0.0
    if plan["write"]:
        material.show_material(obj, d, e)
        # the offset computed in float64 and rounded once, straight into float32 (one pass)
        off = np.empty(pos.shape, dtype=np.float32)
        np.subtract(pos, e.source, out=off, casting="unsafe")
        blender_data.write_offset(obj, d, off, retime=plan["cold"],
                                  sim_key=plan.get("sim_key", ""))
        e.last_inputs = plan["inputs"]
        e.last_cold = plan["cold"]
        e.last_T = plan["T"]
        e.preview_inputs = None
        cache._written_at_undo[key] = cache._undo_serial[0]
    return pos


def frame_key(obj, d, depsgraph=None):
    """A simulation's key of the frame shown (solver.simulation: what the frame is computed
    from besides the frames before it), computed as a solve of it would, without solving."""
    e = binding_of(obj, d)
    T, source, inputs = _solve_inputs(obj, d, e, depsgraph)
    scene = bpy.context.scene
    inputs += _frame_inputs(methods.get(d.method), d, obj, scene)
    plan = _plan_solve(obj, d, e, (obj.name, d.uid), T, source, inputs, True, False, False,
                       False)
    return simulation.frame_key(plan, scene.frame_current)


def binding_of(obj, d):
    """The binding `d` solves with (the cache entry), built or checked against the mesh as a
    solve would: for what works on it between solves (a simulation's checkpoints)."""
    if not d.bound:
        raise DeformKitError("not bound: press Bind")
    blender_data.check_object(obj, d)
    identity.ensure_own_uid(obj, d)
    return binding._entry_for(obj, d, False)


def finish(obj, d, depsgraph=None):
    """Brings the shown result up to date: solves when the inputs changed since the last
    solve, and completes an interactive solve left pending (as the timer would). The vertex
    groups are read again first: Apply must not write a result of groups a script has edited
    without an update that said so."""
    solve(obj, d, depsgraph, check_groups=True)
    key = (obj.name, d.uid)
    if key in cache._cache:
        cache._cache[key].moved_at = 0.0  # settled: whole iterations
    while key in cache._cache and cache._cache[key].pending:
        workers._wait_for_worker(key)  # a slice in a worker thread: its result installs next
        solve(obj, d, depsgraph, interactive=True, resume=True, force=True)


def shown_positions(obj, d):
    """rest + factor * the offset attribute: exactly what the modifier shows (for a method
    following an animated input: that input + factor * the offset)."""
    e = cache._cache.get((obj.name, d.uid))
    me = obj.data
    a = me.attributes.get(d.attribute_name)
    if e is None or a is None or len(a.data) != len(me.vertices):
        raise DeformKitError("%s has no result to apply: bind it first" % d.name)
    off = np.empty(len(me.vertices) * 3, dtype=np.float32)
    a.data.foreach_get("vector", off)
    src = e.rest if e.source is None else e.source
    return src + geonodes.factor(obj, d) * off.reshape(-1, 3).astype(np.float64)


def as_shown(obj, d, e, pos, depsgraph=None):
    """What the modifier shows for the solved positions `pos` of this frame: the input it
    gets + factor * (pos - the positions the method solved from). The input is what reaches
    the modifier (an Armature's pose, shape keys), not the rest: a method that does not
    follow its input solved from the rest, and its offset lands on the input as the
    modifier adds it. A bake writes this, so that its cache, played after the Armature in
    place of the modifier, shows what playback showed (issue 39: it held rest + offset, and
    the rig was thrown away)."""
    inp = moved_input(obj, d, depsgraph)
    base = e.source if inp is None else inp
    return base + geonodes.factor(obj, d) * (pos - e.source)


def deformed_positions(obj, d, depsgraph=None, cold=True, check_groups=False):
    """What the modifier shows on the current frame (as_shown), solved cold as a bake
    solves. `check_groups`: re-read the vertex groups first (a bake's first frame)."""
    pos = solve(obj, d, depsgraph, cold=cold, write=False, force=True,
                check_groups=check_groups)
    return as_shown(obj, d, cache._cache[(obj.name, d.uid)], pos, depsgraph)


def evaluate_object(obj, depsgraph=None, check_groups=False, cold=False, interactive=False,
                    refine=False, only=None, check_topology=None):
    """Handler entry: solves every bound deformer of `obj` whose inputs changed; errors go to
    the deformer's status (and its offset is zeroed), never raised. `refine`: only the
    deformers with a pending interactive solve, continued for another budget (or, for a
    preview, solved in full); `only`: a set of deformer uids to consider."""
    for d in obj.deformkit.deformers:
        if not d.bound or (only is not None and d.uid not in only):
            continue
        try:
            identity.ensure_own_uid(obj, d)  # a duplicate's copy: its own uid before its modifier
        except Exception as ex:  # never let a handler raise
            status.set_status(d, "internal error: %s: %s" % (type(ex).__name__, ex), True)
            continue
        mod = geonodes.find_modifier(obj, d)
        if mod is None or not (mod.show_viewport or mod.show_render):
            continue  # nothing would show it (e.g. replaced by a baked cache)
        geonodes.repair(mod, d)  # an Attribute input edited in the modifier's panel
        key = (obj.name, d.uid)
        if refine and not (key in cache._cache and cache._cache[key].pending):
            continue
        try:
            if solve(obj, d, depsgraph, cold=cold, check_groups=check_groups,
                     interactive=interactive, force=refine, resume=refine,
                     check_topology=check_topology) is not None:
                status.reset_status(d)
        except rebind.RebindPending:
            pass  # the last result stays shown; finish_rebinds installs the new binding
        except DeformKitError as ex:
            if d.status != str(ex):
                blender_data.zero_offset(obj, d)
                cache.drop(obj.name, d.uid)
            status.set_status(d, ex, True)
        except Exception as ex:  # never let a handler raise
            status.set_status(d, "internal error: %s: %s" % (type(ex).__name__, ex), True)

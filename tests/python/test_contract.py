"""The method contract through the Python API, for every method class the module registers
(deformkit.METHODS, from the native registry): a new method gets these tests by being
registered. What a method promises beyond the common part comes from the native contract's
flags (deformkit._native._method_info). The add-on's registry must list the same classes.

Checked on a bumpy grid with a handle at each end and a fixed row, and on an icosphere with
one handle cap:
- zero drag gives the rest mesh, from positions and from transforms;
- positions and transforms of the same targets agree (translations only where the method
  says transforms are not positions);
- rebind with the same constraints equals a fresh bind;
- with nothing fixed, a rigid motion (or translation) of every handle is reproduced where the
  method promises it, and the handles are always met;
- cold solves are deterministic, bit for bit;
- start_positions: a method with given_start returns its converged result from it, puts the
  constrained vertices in place and depends on the request alone; other iterative methods
  refuse it, direct ones ignore it;
- every malformed input raises the same exception type from every method, and a refused
  call leaves the object answering as before.
A dynamic method (a simulation: ShapeMatching) is held to the same with its own meaning of
the starts: a cold solve resets the simulation to the request (its first frame), a warm or
resumed one advances a frame, start_positions releases the shape there; it simulates loose
parts instead of holding them, and needs no handle.
"""
import importlib.util
import math
import os
import re

import numpy as np
import pytest

import deformkit as dk
from conftest import CONTROL_METHODS, GROUP_METHODS, make_grid, make_icosphere

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def info(name):
    return dk._native._method_info(name)


def cold(name):
    """Solve keywords that start from the rest state."""
    return {"warm_start": False} if info(name)["iterative"] else {}


def rotation(angle=0.4, axis=(1.0, 2.0, 2.0)):
    a = np.asarray(axis, dtype=float)
    a /= np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def transform(R=np.eye(3), t=(0.1, -0.05, 0.2)):
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def scenes():
    v, f = make_grid(12, 10, bump=0.15, jitter=0.2)
    left, right = np.where(v[:, 0] <= 1e-9)[0], np.where(v[:, 0] >= 1 - 1e-9)[0]
    row = np.where((v[:, 1] <= 1e-9) & (v[:, 0] > 1e-9) & (v[:, 0] < 1 - 1e-9))[0]
    yield "grid", v, f, [left, right], row
    v, f = make_icosphere(2)
    cap, top = np.where(v[:, 2] <= -0.8)[0], np.where(v[:, 2] >= 0.8)[0]
    yield "icosphere", v, f, [cap], top


SCENES = list(scenes())
CASES = [(m, s) for m in GROUP_METHODS for s in SCENES]
IDS = ["%s-%s" % (m, s[0]) for m, s in CASES]


def bind(name, scene, **kw):
    _, v, f, handles, fixed = scene
    return getattr(dk, name)(dk.Mesh(v, f), handles=handles, fixed=fixed, **kw)


def test_registries_agree():
    spec = importlib.util.spec_from_file_location("_addon_methods",
                                                  os.path.join(ROOT, "addon", "methods.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    # every native method is in the add-on's registry, each read by the collector of its
    # control kinds (addon/solver/controls.py: vertex groups, a lattice, a cage)
    assert sorted(m.native_class for m in mod.METHODS) == sorted(dk.METHODS)
    assert CONTROL_METHODS and set(GROUP_METHODS) | set(CONTROL_METHODS) == set(dk.METHODS)
    src = open(os.path.join(ROOT, "addon", "solver", "controls.py")).read()
    collected = set(re.search(r"COLLECTORS = \{(.*?)\}", src, re.S).group(1).split('"')[1::2])
    assert all(set(info(m.native_class)["controls"]) & collected for m in mod.METHODS)
    # what the add-on's registry repeats of the native table agrees with it
    assert all(m.graph == info(m.native_class)["graph"] for m in mod.METHODS)
    for name in dk.METHODS:
        assert isinstance(getattr(dk, name), type)
        assert set(info(name)) == {"iterative", "transforms_as_positions",
                                   "translation_invariant", "rigid_invariant",
                                   "penalty_handles", "soft_regions", "given_start",
                                   "edits_input", "graph", "controls", "state",
                                   "linear_precision", "dynamic", "interior"}
        # a warm start reads what the last solve left: every iterative method carries state
        assert info(name)["state"] or not info(name)["iterative"], name
        # the control kinds its bind takes (dk_controls.h): a non-empty tuple of known ids
        kinds = info(name)["controls"]
        assert isinstance(kinds, tuple) and kinds and set(kinds) <= {
            "vertex_groups", "points", "bones", "cage", "lattice", "poses"}, (name, kinds)
    with pytest.raises(KeyError):
        info("NoSuchMethod")


BOX_TRIANGLES = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                          [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])


def bind_control(name, v, f):
    """A method bound to a control, its control around the vertices v: a lattice with its
    defaults, a box cage over their bounding box grown by a tenth, or two bones (one at the
    origin, one at the box's centre, turned) with weights ramping along x (a new control
    kind needs its scene here, as in test_contract.c)."""
    kinds = info(name)["controls"]
    if "lattice" in kinds:
        return getattr(dk, name)(dk.Mesh(v, f))
    lo, hi = v.min(axis=0), v.max(axis=0)
    if "bones" in kinds:
        B = np.repeat(np.eye(4)[None], 2, axis=0)
        B[1, :3, :3] = rotation(0.3)
        B[1, :3, 3] = 0.5 * (lo + hi)
        w = (v[:, 0] - lo[0]) / max(hi[0] - lo[0], 1e-300)
        return getattr(dk, name)(dk.Mesh(v, f), bone_frames=B, weights=np.c_[1 - w, w])
    assert "cage" in kinds, "no contract scene for %s's controls %s" % (name, kinds)
    pad = 0.1 * (hi - lo) + 1e-3 * np.linalg.norm(hi - lo)
    corners = np.array([[(q >> d) & 1 for d in range(3)] for q in range(8)], dtype=float)
    box = lo - pad + corners * (hi - lo + 2 * pad)
    return getattr(dk, name)(dk.Mesh(v, f), cage_vertices=box, cage_triangles=BOX_TRIANGLES)


class ControlTargets:
    """What a control method's solve takes, whatever the kind: its points' positions
    (targets=, rest_points) or its bones' frames (transforms=, rest_frames)."""

    def __init__(self, m):
        self.m = m
        self.frames = hasattr(m, "rest_frames")
        self.rest = np.asarray(m.rest_frames if self.frames else m.rest_points)

    def solve(self, x, **kw):
        return self.m.solve(transforms=x, **kw) if self.frames else self.m.solve(x, **kw)

    def translated(self, x, t):
        y = x.copy()
        if self.frames:
            y[:, :3, 3] += t
        else:
            y += t
        return y

    def bent(self, scale):
        y = self.rest.copy()
        if self.frames:
            y[:, :3, :] += 0.1 * scale * np.sin(3 * y[:, :3, :] / scale)
        else:
            y += 0.1 * scale * np.sin(3 * y / scale)
        return y

    def other_kind(self):
        """A request of the kind it refuses."""
        return (lambda: self.m.solve(np.zeros((2, 3)))) if self.frames else \
            (lambda: self.m.solve(transforms=[np.eye(4)]))


@pytest.mark.parametrize("name", CONTROL_METHODS)
@pytest.mark.parametrize("scene", SCENES, ids=[s[0] for s in SCENES])
def test_a_method_bound_to_a_control(name, scene):
    """A method bound to a control (a lattice, a cage, bones) with its defaults, at any scale
    and place: its control at rest gives the mesh back bit for bit; a translation translates
    it; an affine map maps it (linear_precision); cold solves repeat; a refused request
    (NaN, the other kind of targets, a wrong count) raises and changes nothing; a pose with
    the control at rest is returned; a method that takes no handles refuses them."""
    _, v, f, handles, fixed = scene
    for scale, shift in ((1.0, 0.0), (1e-3, 5e3), (250.0, -40.0)):
        vs = v * scale + shift
        c = ControlTargets(bind_control(name, vs, f))
        m, rest = c.m, c.rest
        assert np.array_equal(c.solve(rest).positions, vs)
        t = np.array([0.3, -0.2, 0.7]) * scale
        np.testing.assert_allclose(c.solve(c.translated(rest, t)).positions, vs + t, rtol=0,
                                   atol=1e-12 * scale * 1e3 + 1e-9 * abs(shift))
        if info(name)["linear_precision"]:
            A = rotation() * 1.2
            got = m.solve(rest @ A.T + t).positions
            np.testing.assert_allclose(got, vs @ A.T + t, rtol=0,
                                       atol=1e-9 * (scale + abs(shift)))
        bent = c.bent(scale)
        a = c.solve(bent)
        b = c.solve(bent)
        assert np.array_equal(a.positions, b.positions)
        assert m.energy(a.positions) == pytest.approx(a.energy, rel=1e-12)
        bad = bent.copy()
        bad.reshape(len(bad), -1)[1, 2] = np.nan
        with pytest.raises(ValueError):
            c.solve(bad)
        with pytest.raises((ValueError, TypeError)):
            c.other_kind()()
        with pytest.raises(ValueError):
            c.solve(bent[:-1])
        assert np.array_equal(c.solve(bent).positions, a.positions)
        if info(name)["edits_input"]:
            pose = vs + 0.01 * scale * np.cos(vs / scale)
            assert np.array_equal(c.solve(rest, input_positions=pose).positions, pose)
    with pytest.raises(TypeError):
        getattr(dk, name)(dk.Mesh(v, f), handles)


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_zero_drag_is_rest(name, scene):
    _, v, f, handles, fixed = scene
    m = bind(name, scene)
    r = m.solve(np.concatenate([v[h] for h in handles]), **cold(name))
    np.testing.assert_allclose(r.positions, v, atol=1e-9)
    r = m.solve(transforms=[np.eye(4)] * len(handles), **cold(name))
    np.testing.assert_allclose(r.positions, v, atol=1e-9)


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_positions_and_transforms_agree(name, scene):
    _, v, f, handles, fixed = scene
    R = rotation() if info(name)["transforms_as_positions"] else np.eye(3)
    Ts = [transform(R, (0.1 + 0.05 * k, -0.05, 0.2)) for k in range(len(handles))]
    targets = np.concatenate([v[h] @ T[:3, :3].T + T[:3, 3] for h, T in zip(handles, Ts)])
    a = bind(name, scene).solve(targets, **cold(name))
    b = bind(name, scene).solve(transforms=Ts, **cold(name))
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-7)
    allh = np.concatenate(handles)
    err = np.abs(a.positions[allh] - targets).max(axis=1)
    move = np.abs(targets - v[allh]).max()
    soft = info(name)["soft_regions"]
    if info(name)["penalty_handles"] or soft:   # most of the way (see test_contract.c)
        assert err.mean() <= (0.5 if soft else 0.25) * move
    else:
        assert err.max() <= 1e-9
    if soft:   # a least-squares fit holds the vertices outside the regions, fixed or not
        assert np.abs(a.positions[fixed] - v[fixed]).max(axis=1).mean() <= 0.5 * move
    else:
        np.testing.assert_allclose(a.positions[fixed], v[fixed], atol=1e-9)


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_preview_is_fast_path_or_the_solve(name, scene):
    # solve(preview=True): ARAP's start (no iterations), EigenDeformation's Steps 1-2, and
    # for every other method its ordinary solve; a preview then a resume ends where a warm
    # solve does (to the method's tolerance)
    _, v, f, handles, fixed = scene
    T = [transform(rotation(0.3))] * len(handles)
    # a penalty method's Gauss-Newton stops anywhere within its tolerance's reach of the
    # minimum (sqrt(1e-6) of the steps); tight, the two paths must meet
    kw = {"tolerance": 1e-10} if info(name)["penalty_handles"] else {}
    a, b = bind(name, scene, **kw), bind(name, scene, **kw)
    p = a.solve(transforms=T, preview=True)
    q = b.solve(transforms=T)
    assert np.isfinite(np.asarray(p.positions)).all()
    if name in ("ARAP", "VolumetricARAP"):  # the start alone (the solver inside is ARAP)
        assert p.iterations == 0
        np.testing.assert_allclose(np.asarray(p.positions)[np.concatenate(handles)],
                                   np.asarray(q.positions)[np.concatenate(handles)], atol=1e-12)
    elif name == "EigenDeformation":
        assert p.iterations == 0
    else:
        np.testing.assert_allclose(p.positions, q.positions, atol=1e-12)
    r = a.solve(transforms=T, resume=True) if info(name)["iterative"] else a.solve(transforms=T)
    if info(name)["dynamic"]:   # every warm solve, resumed or not, advances a frame
        assert np.array_equal(r.positions, b.solve(transforms=T).positions)
        return
    np.testing.assert_allclose(r.positions, q.positions, atol=1e-4)


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_rebind_equals_fresh_bind(name, scene):
    _, v, f, handles, fixed = scene
    T = [transform(rotation(0.3))] * len(handles)
    m = bind(name, scene)
    m.solve(transforms=T, **cold(name))
    m.rebind(handles=handles, fixed=fixed)
    a = m.solve(transforms=T, **cold(name))
    b = bind(name, scene).solve(transforms=T, **cold(name))
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-12)
    assert a.iterations == b.iterations


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_rigid_motion_of_every_constraint(name, scene):
    _, v, f, handles, fixed = scene
    flags = info(name)
    R = rotation() if flags["rigid_invariant"] else np.eye(3)
    T = transform(R)
    # see test_contract.c; a dynamic method's cold solve is its first frame (no iterations)
    kw = {"max_iterations": 2000} if flags["iterative"] and not flags["dynamic"] else {}
    if flags["soft_regions"]:   # every vertex outside the regions is held: move them all
        handles = [np.arange(len(v))]
        flags = dict(flags, rigid_invariant=True)
        R = rotation()
        T = transform(R)
    m = getattr(dk, name)(dk.Mesh(v, f), handles=handles, **kw)
    r = m.solve(transforms=[T] * len(handles), **cold(name))
    want = v @ R.T + T[:3, 3]
    allh = np.concatenate(handles)
    tol = 1e-4 if flags["penalty_handles"] else 1e-9   # penalty: to the solver's tolerance
    np.testing.assert_allclose(r.positions[allh], want[allh], atol=tol)
    if flags["rigid_invariant"] or flags["translation_invariant"]:
        np.testing.assert_allclose(r.positions, want, atol=max(tol, 1e-6))


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_a_restored_state_continues_the_shot(name):
    """save_state() mid-shot, other solves, restore_state() into the same object and into a
    fresh one (a chunk in another process): the rest of the shot is bit for bit what an
    object never interrupted gives. A state that does not fit raises ValueError and changes
    nothing; a method without state raises TypeError."""
    scene = SCENES[0]
    m = bind(name, scene)
    if not info(name)["state"]:
        with pytest.raises(TypeError, match="carries no state"):
            m.save_state()
        with pytest.raises(TypeError, match="carries no state"):
            m.restore_state(b"")
        return
    n = len(scene[3])
    pose = scene[1] + [0.0, 0.0, 0.05] * scene[1][:, :1] ** 2
    edits = info(name)["edits_input"]

    def shot(obj, steps):
        out = []
        for k in steps:
            kw = dict(transforms=[transform(rotation(0.2 * k), (0.1 * k, 0, 0))] * n)
            if k >= 2 and edits:
                kw["input_positions"] = pose
            if k == 1:
                kw["max_iterations"] = 1   # a slice: the next one resumes it
            if k == 2:
                kw = dict(kw, transforms=[transform(rotation(0.2), (0.1, 0, 0))] * n,
                          resume=True)
                kw.pop("input_positions", None)
            out.append(obj.solve(**kw))
        return out

    ref = shot(bind(name, scene), range(5))
    shot(m, range(2))
    state = m.save_state()
    assert isinstance(state, bytes) and len(state) > 0
    shot(m, [4, 3])
    m.restore_state(bytearray(state))
    fresh = bind(name, scene)
    fresh.restore_state(memoryview(state))
    for obj in (m, fresh):
        got = shot(obj, range(2, 5))
        for a, b in zip(ref[2:], got):
            assert np.array_equal(a.positions, b.positions) and a.iterations == b.iterations
    other = getattr(dk, name)(dk.Mesh(scene[1], scene[2]), handles=scene[3][:1],
                              fixed=scene[4])
    before = other.save_state()
    with pytest.raises(ValueError, match="bound otherwise"):
        other.restore_state(state)
    with pytest.raises(ValueError, match="bytes"):
        m.restore_state(state[:-1])
    with pytest.raises(TypeError):
        m.restore_state(42)
    assert other.save_state() == before


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_cold_solves_are_deterministic(name, scene):
    _, v, f, handles, fixed = scene
    m = bind(name, scene)
    T = [transform(rotation(0.5))] * len(handles)
    a = m.solve(transforms=T, **cold(name))
    m.solve(transforms=[transform(rotation(-0.2), (0.3, 0, 0))] * len(handles))
    b = m.solve(transforms=T, **cold(name))
    assert np.array_equal(a.positions, b.positions) and a.iterations == b.iterations


BAD_SOLVES = [
    ("NaN target", lambda n, hv: dict(targets=np.full((hv, 3), np.nan)), ValueError),
    ("wrong target count", lambda n, hv: dict(targets=np.zeros((hv + 1, 3))), ValueError),
    ("wrong transform count", lambda n, hv: dict(transforms=[np.eye(4)] * (n + 1)), ValueError),
    ("non-affine transform", lambda n, hv: dict(transforms=[np.ones((4, 4))] * n), ValueError),
    ("both targets and transforms",
     lambda n, hv: dict(targets=np.zeros((hv, 3)), transforms=[np.eye(4)] * n), TypeError),
    ("neither", lambda n, hv: dict(), TypeError),
]


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_bad_solves_raise_the_same_type_and_change_nothing(name):
    scene = SCENES[0]
    _, v, f, handles, fixed = scene
    m = bind(name, scene)
    T = [transform(rotation(0.2))] * len(handles)
    before = m.solve(transforms=T, **cold(name)).positions
    hv = sum(len(h) for h in handles)
    for what, args, exc in BAD_SOLVES:
        with pytest.raises(exc):
            m.solve(**args(len(handles), hv))
    after = m.solve(transforms=T, **cold(name)).positions
    assert np.array_equal(before, after)


BAD_BINDS = [
    ("handle index out of range", lambda v, h, fx: dict(handles=[[len(v)]]), IndexError),
    ("negative handle index", lambda v, h, fx: dict(handles=[[-1]]), IndexError),
    ("no handle", lambda v, h, fx: dict(handles=[]), ValueError),
    ("empty handle", lambda v, h, fx: dict(handles=[[]]), ValueError),
    ("vertex in two handles", lambda v, h, fx: dict(handles=[h[0], h[0][:1]]), ValueError),
    ("handle and fixed overlap", lambda v, h, fx: dict(handles=h, fixed=h[0][:1]), ValueError),
    ("fixed index out of range", lambda v, h, fx: dict(handles=h, fixed=[len(v)]), IndexError),
    ("handle weight out of (0, 1]",
     lambda v, h, fx: dict(handles=h, handle_weights=[np.full(len(x), 1.5) for x in h]),
     ValueError),
]


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_bad_binds_raise_the_same_type(name):
    _, v, f, handles, fixed = SCENES[0]
    mesh = dk.Mesh(v, f)
    cls = getattr(dk, name)
    for what, args, exc in BAD_BINDS:
        if what == "no handle" and info(name)["dynamic"]:
            continue   # a simulation needs no handle (tests/python/test_shape_matching.py)
        with pytest.raises(exc):
            cls(mesh, **args(v, handles, fixed))


class _Sentinel:
    pass


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_reference_cycles_are_collected(name):
    """A method object in a reference cycle is freed by the garbage collector: here the
    handle list it remembers holds a sentinel that holds the object. Without the object's
    traverse support the collector cannot see the cycle, and the sentinel stays alive."""
    import gc
    import weakref
    _, v, f, handles, fixed = SCENES[0]
    h = list(handles)
    m = getattr(dk, name)(dk.Mesh(v, f), handles=h, fixed=fixed)
    m.solve(transforms=[np.eye(4)] * len(handles))
    s = _Sentinel()
    s.method = m
    h.append(s)                 # m -> its remembered handles h -> s -> m
    alive = weakref.ref(s)
    del m, h, s
    gc.collect()
    assert alive() is None


# Loose geometry (issue 18, class 12): components that no handle or fixed vertex reaches --
# loose vertices, a floating triangle -- are held at rest by every method (the shared
# constraint layer decides it), counted in stats and named in warnings; a mesh whose every
# vertex is constrained gives the constrained motion.

def loose_scene():
    _, v, f, handles, fixed = SCENES[0]
    n = len(v)
    extra = np.array([[0.5, 0.5, 3.0], [0.4, 0.5, 4.0], [0.3, 0.6, 5.0],
                      [0.5, 0.2, 2.0], [0.6, 0.2, 2.0], [0.5, 0.3, 2.5]])
    return (np.vstack([v, extra]), np.vstack([f, [[n + 3, n + 4, n + 5]]]), handles, fixed, n)


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_loose_geometry_is_held_at_rest(name):
    v, f, handles, fixed, n0 = loose_scene()
    m = getattr(dk, name)(dk.Mesh(v, f), handles=handles, fixed=fixed)
    if info(name)["dynamic"]:
        # simulated, not held: at rest they stay (a cold solve, then a frame)
        assert m.stats["n_held"] == 0 and m.warnings == ()
        targets = np.concatenate([v[h] + [0, 0, 0.2] for h in handles])
        for kw in ({"warm_start": False}, {}):
            r = m.solve(targets, **kw)
            assert np.abs(r.positions[n0:] - v[n0:]).max() < 1e-12
        return
    assert m.stats["n_held"] == 6 and m.stats["n_held_components"] == 4
    assert len(m.warnings) == 1 and "6 vertices in 4 connected components" in m.warnings[0]
    assert "first: vertex %d)" % n0 in m.warnings[0]
    targets = np.concatenate([v[h] + [0, 0, 0.2] for h in handles])
    rest_normals = m.normals() if name == "EmbeddedDeformation" else None
    r = m.solve(targets, **cold(name))
    assert np.array_equal(r.positions[n0:], v[n0:])
    if name == "EmbeddedDeformation":   # held vertices keep their rest normals too
        assert np.array_equal(m.normals()[n0:], rest_normals[n0:])
        assert np.array_equal(m.deformed()[n0:], v[n0:])
    assert np.abs(r.positions[np.concatenate(handles), 2] - v[np.concatenate(handles), 2]).max() > 0.05
    # a constrained loose vertex follows its constraint
    m = getattr(dk, name)(dk.Mesh(v, f), handles=list(handles) + [[n0]], fixed=fixed)
    assert m.stats["n_held"] == 5
    r = m.solve(np.concatenate([targets, [v[n0] + [0.1, 0, 0]]]), **cold(name))
    if not (info(name)["penalty_handles"] or info(name)["soft_regions"]):
        np.testing.assert_allclose(r.positions[n0], v[n0] + [0.1, 0, 0], atol=1e-12)
    # nothing held: no warning
    assert getattr(dk, name)(dk.Mesh(*SCENES[0][1:3]), handles=handles).warnings == ()


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_every_vertex_constrained_gives_the_constrained_motion(name):
    _, v, f, handles, fixed = SCENES[0]
    allh = np.concatenate(handles)
    rest = np.setdiff1d(np.arange(len(v)), allh)
    m = getattr(dk, name)(dk.Mesh(v, f), handles=handles, fixed=rest)
    targets = np.concatenate([v[h] + [0, 0, 0.2] for h in handles])
    r = m.solve(targets, **cold(name))
    assert np.isfinite(r.positions).all()
    if not (info(name)["penalty_handles"] or info(name)["soft_regions"]):
        np.testing.assert_allclose(r.positions[allh], targets, atol=1e-12)
        np.testing.assert_allclose(r.positions[rest], v[rest], atol=1e-12)


@pytest.mark.heavy
@pytest.mark.parametrize("name", GROUP_METHODS)
def test_stanford_bunny_with_its_loose_vertices(name, shared_mesh):
    """The real example: the Stanford bunny carries 1,113 vertices on no face. Every method
    binds and solves it with a handle and a fixed set on the surface; the loose vertices
    stay exactly at rest and are reported."""
    mesh = dk.read_mesh(shared_mesh("stanford-bunny.obj"))
    v = mesh.vertices
    on_face = np.zeros(len(v), bool)
    on_face[mesh.triangles.ravel()] = True
    assert (~on_face).sum() == 1113
    surface = np.flatnonzero(on_face)
    order = surface[np.argsort(v[surface, 1])]
    fixed, handle = order[:300], order[-300:]
    # (EigenDeformation with 50 eigenvectors, not 300: the loose vertices take the same path,
    # and the default basis alone is 20 s of this suite; tests/python/test_eigen.py covers it)
    kw = {"n_eigenvectors": 50} if name == "EigenDeformation" else {}
    m = getattr(dk, name)(mesh, handles=[handle], fixed=fixed, **kw)
    held = 0 if info(name)["dynamic"] else 1113   # a simulation holds nothing: at rest
    assert m.stats["n_held"] == held and m.stats["n_held_components"] == held
    r = m.solve(v[handle] + [0, 0.01, 0], **cold(name))
    assert np.isfinite(r.positions).all()
    assert np.array_equal(r.positions[~on_face], v[~on_face])
    assert np.abs(r.positions[handle] - v[handle]).max() > 0.002


@pytest.mark.parametrize("name", GROUP_METHODS)
def test_rebind_into_and_out_of_every_vertex_constrained(name):
    _, v, f, handles, fixed = SCENES[0]
    mesh = dk.Mesh(v, f)
    allh = np.concatenate(handles)
    rest = np.setdiff1d(np.arange(len(v)), allh)
    targets = np.concatenate([v[h] + [0, 0, 0.2] for h in handles])
    m = getattr(dk, name)(mesh, handles=handles, fixed=fixed)
    m.solve(targets, **cold(name))
    m.rebind(fixed=rest)
    a = m.solve(targets, **cold(name))
    b = getattr(dk, name)(mesh, handles=handles, fixed=rest).solve(targets, **cold(name))
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-12)
    m.rebind(fixed=fixed)
    a = m.solve(targets, **cold(name))
    b = getattr(dk, name)(mesh, handles=handles, fixed=fixed).solve(targets, **cold(name))
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-12)


BAD_STARTS = [
    ("NaN start", lambda v: dict(start_positions=np.full(v.shape, np.nan))),
    ("start with a vertex too few", lambda v: dict(start_positions=v[:-1])),
    ("start and resume", lambda v: dict(start_positions=v, resume=True)),
]


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_given_start(name, scene):
    """start_positions: a method that starts from positions (given_start) puts the
    constrained vertices in place, returns a converged result from it unchanged, and
    depends on the request alone; other iterative methods refuse it; direct ones ignore it.
    Malformed starts raise ValueError from every method and change nothing."""
    _, v, f, handles, fixed = scene
    m = bind(name, scene)
    T = [transform(rotation(0.5))] * len(handles)
    a = m.solve(transforms=T, **cold(name))
    for what, args in BAD_STARTS:
        with pytest.raises(ValueError):
            m.solve(transforms=T, **args(v))
    assert np.array_equal(m.solve(transforms=T, **cold(name)).positions, a.positions)
    noisy = v + np.random.default_rng(3).normal(0, 0.02, v.shape)
    if info(name)["given_start"]:
        assert info(name)["iterative"]
        # from its own converged result: the same minimum, at once
        b = m.solve(transforms=T, start_positions=a.positions)
        # (a volume's interior, not in the positions, is rebuilt and relaxes in a few steps)
        assert b.converged and b.iterations <= (5 if info(name)["interior"] else 2)
        assert abs(b.energy - a.energy) <= 1e-9 * max(a.energy, 1e-12)
        np.testing.assert_allclose(b.positions, a.positions, atol=1e-6)
        # the start alone: constrained vertices in place, the others where given
        p = m.solve(transforms=T, start_positions=noisy, preview=True)
        held = np.concatenate(handles + [np.asarray(fixed)])
        free = np.setdiff1d(np.arange(len(v)), held)
        np.testing.assert_allclose(p.positions[fixed], v[fixed], atol=0)
        np.testing.assert_allclose(p.positions[handles[0]], a.positions[handles[0]],
                                   atol=1e-12)
        assert np.array_equal(p.positions[free], noisy[free])
        # the request alone decides: the same result after other solves in between
        c = m.solve(transforms=T, start_positions=noisy)
        m.solve(transforms=[transform(rotation(-0.3), (0.2, 0, 0))] * len(handles))
        d = m.solve(transforms=T, start_positions=noisy)
        assert np.array_equal(c.positions, d.positions) and c.iterations == d.iterations
        if info(name)["dynamic"]:   # released there at rest: the start is the result
            assert np.array_equal(c.positions, p.positions)
        else:
            assert c.converged and abs(c.energy - a.energy) <= 1e-4 * a.energy
    elif info(name)["iterative"]:
        with pytest.raises(ValueError, match="given positions"):
            m.solve(transforms=T, start_positions=v)
        assert np.array_equal(m.solve(transforms=T, **cold(name)).positions, a.positions)
    else:
        b = m.solve(transforms=T, start_positions=noisy)
        assert np.array_equal(b.positions, a.positions)


@pytest.mark.parametrize("name,scene", CASES, ids=IDS)
def test_input_positions(name, scene):
    """input_positions: a method that edits an input (edits_input) treats it as this solve's
    rest. Targets where the input puts the handles give the input exactly; a rigid motion
    of the rest as the input gives the rest's result moved rigidly (rigid-invariant methods;
    the others, a translation); then a solve without it is the rest's again, bit for bit.
    Bad inputs raise ValueError and change nothing. A method that does not edit an input
    refuses one, never ignores it."""
    _, v, f, handles, fixed = scene
    m = bind(name, scene)
    T = [transform(rotation(0.5), (0.1, 0.2, 0))] * len(handles)
    a = m.solve(transforms=T, **cold(name))
    hv = np.concatenate(handles)
    if not info(name)["edits_input"]:
        with pytest.raises(ValueError, match="input_positions"):
            m.solve(transforms=T, input_positions=v, **cold(name))
        assert np.array_equal(m.solve(transforms=T, **cold(name)).positions, a.positions)
        return
    for bad in (v[:-1], np.where(np.arange(v.size).reshape(v.shape) == 4, np.nan, v),
                np.full(v.shape, 1e300)):
        with pytest.raises(ValueError):
            m.solve(transforms=T, input_positions=bad, **cold(name))
    assert np.array_equal(m.solve(transforms=T, **cold(name)).positions, a.positions)
    flags = info(name)
    R = rotation(0.7) if flags["rigid_invariant"] else np.eye(3)
    t = np.array([0.3, -1.2, 2.0])
    moved = v @ R.T + t
    z = m.solve(moved[hv], input_positions=moved, **cold(name))
    np.testing.assert_allclose(z.positions, moved, atol=1e-9)
    kw = dict(cold(name), **({"max_iterations": 2000} if flags["iterative"] else {}))
    a = m.solve(transforms=T, **kw)
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    b = m.solve(transforms=[M @ np.asarray(x) @ np.linalg.inv(M) for x in T],
                input_positions=moved, **kw)
    np.testing.assert_allclose(b.positions, a.positions @ R.T + t, atol=1e-6)
    assert np.array_equal(m.solve(transforms=T, **kw).positions, a.positions)


# The add-on's option defaults are the Python API's (the brief: "Python defaults and the
# add-on's defaults agree"), as each class's docstring signature states them. Where they may
# differ, the reason is listed here (the second hostile review found LaplacianEdit's detail
# 'fixed' in Python and 'local_frame' in the add-on, Falloff's 10 hops against the add-on's
# automatic reach, and LinearReconstruction's material read the other way round).
DEFAULTS_MAY_DIFFER = {
    # the add-on's Range options are two (a length, and edges for hops); 0 = automatic in
    # both, which is the native range=0
    ("FALLOFF", "range_length"), ("FALLOFF", "range_hops"),
}


def _docstring_defaults(cls):
    sig = cls.__doc__.split("\n\n")[0]
    out = {}
    for m in re.finditer(r"(\w+)=('[^']*'|\"[^\"]*\"|[-+\w.]+)", sig):
        out[m.group(1)] = m.group(2).strip("'\"")
    return out


def test_addon_defaults_are_the_python_defaults():
    spec = importlib.util.spec_from_file_location("_addon_methods2",
                                                  os.path.join(ROOT, "addon", "methods.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    checked = 0
    for m in mod.METHODS:
        doc = _docstring_defaults(getattr(dk, m.native_class))
        for o in m.options:
            kw = o.keyword
            if kw is None or (m.id, o.name) in DEFAULTS_MAY_DIFFER or kw not in doc:
                continue
            want = doc[kw]
            got = o.default
            if isinstance(got, bool):
                same = want == str(got)
            elif isinstance(got, (int, float)):
                same = (got == 0 and want in ("auto", "None")) or (
                    want not in ("auto", "None") and float(want) == float(got))
            else:
                same = want == str(got)
            assert same, "%s.%s: the add-on's default %r, Python's %r" % (
                m.native_class, kw, got, want)
            checked += 1
    assert checked > 20

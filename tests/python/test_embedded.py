"""Embedded deformation (deformkit.EmbeddedDeformation; Sumner, Schmid & Pauly 2007): what is
its own beyond the contract tests (tests/python/test_contract.py): the graph, the paper's
bumpy plane (Figure 3), exact rigid motions, fixed nodes, several components, bad input."""
import numpy as np
import pytest

import deformkit as dk
from conftest import make_grid, make_icosphere


def bumpy_plane(n=60, bumps=6, seed=3):
    """An n x n-cell grid on [0, 1]^2 with smooth Gaussian bumps (Figure 3's setting)."""
    xs, ys = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    x, y = xs.ravel(), ys.ravel()
    z = np.zeros_like(x)
    centres = np.random.default_rng(seed).uniform(0.25, 0.75, (bumps, 2))
    for cx, cy in centres:
        z += 0.04 * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * 0.04 ** 2))
    v = np.stack([x, y, z], 1)
    faces = []
    for i in range(n):
        for j in range(n):
            a, b = i * (n + 1) + j, (i + 1) * (n + 1) + j
            faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    return v, np.array(faces), centres


def kabsch_rms(p, q):
    """RMS residual of the best rigid fit of point set p onto q."""
    pc, qc = p - p.mean(0), q - q.mean(0)
    u, _, vt = np.linalg.svd(pc.T @ qc)
    d = np.sign(np.linalg.det(u @ vt))
    r = u @ np.diag([1, 1, d]) @ vt
    return np.sqrt(np.mean(np.sum((pc @ r - qc) ** 2, axis=1)))


def test_graph_is_seeded_and_sized():
    v, f = make_icosphere(3)
    mesh = dk.Mesh(v, f)
    a = dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=80)
    b = dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=80)
    c = dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=80, seed=7)
    assert np.array_equal(a.nodes, b.nodes) and np.array_equal(a.edges, b.edges)
    assert not np.array_equal(a.nodes, c.nodes)
    assert 60 <= len(a.nodes) <= 80                      # the bisection lands just under
    # nodes lie on the surface (the unit sphere, within its chord error) and are spread out
    r = np.linalg.norm(a.nodes, axis=1)
    assert np.all(r > 0.97) and np.all(r <= 1.0 + 1e-12)
    d = np.linalg.norm(a.nodes[:, None] - a.nodes[None], axis=2) + np.eye(len(a.nodes)) * 9
    assert d.min() > 0.5 * np.median(d.min(axis=1))
    e = a.edges
    assert e.shape[1] == 2 and np.all(e[:, 0] < e[:, 1]) and len(np.unique(e, axis=0)) == len(e)
    # vertex nodes: the nodes are mesh vertices
    g = dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=80, nodes="vertices")
    assert all(np.abs(v - p).sum(axis=1).min() == 0.0 for p in g.nodes)


def test_zero_drag_returns_the_input():
    v, f, _ = bumpy_plane(30)
    fixed = np.where(v[:, 0] <= 1e-9)[0]
    handle = np.where(v[:, 0] >= 1 - 1e-9)[0]
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=100)
    r = ed.solve(v[handle], warm_start=False)
    assert np.abs(r.positions - v).max() <= 1e-12
    assert r.energy <= 1e-20


def test_rigid_motion_of_all_handles_is_exact():
    v, f = make_icosphere(3)
    mesh = dk.Mesh(v, f)
    caps = [np.where(v[:, 2] < -0.6)[0], np.where(v[:, 2] > 0.6)[0]]
    ed = dk.EmbeddedDeformation(mesh, handles=caps, n_nodes=100, tolerance=1e-12,
                                max_iterations=100)
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (0.3, -0.2, 0.5)
    r = ed.solve(transforms=[T, T], warm_start=False)
    assert np.abs(r.positions - (v @ R.T + T[:3, 3])).max() <= 1e-8
    assert r.energy <= 1e-12
    X = ed.transforms            # every node: the same rotation, t = the motion of its node
    assert np.abs(X[:, :9] - R.ravel()).max() <= 1e-8
    g = ed.nodes
    assert np.abs(X[:, 9:] - (g @ R.T + T[:3, 3] - g)).max() <= 1e-8


@pytest.mark.parametrize("where", ["caps", "everywhere"])
def test_gauss_newton_steps_are_exact(where):
    """Each step solves J^T J d = -J^T f exactly (schur.c eliminates the rotations of the
    nodes no positional term shares, and keeps the others): on a rigid motion of the
    handles, whose minimum has no residual, Gauss-Newton then converges quadratically, each
    F about the square of the one before; an inexact or wrong step converges linearly. With
    handles on two small caps most nodes are eliminated (about two in three); with one
    handle everywhere, none."""
    v, f = make_icosphere(3)
    mesh = dk.Mesh(v, f)
    handles = ([np.where(v[:, 2] < -0.9)[0], np.where(v[:, 2] > 0.9)[0]]
               if where == "caps" else [np.arange(len(v))])
    ed = dk.EmbeddedDeformation(mesh, handles=handles, n_nodes=100, tolerance=1e-12)
    a = 0.7
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    T[:3, 3] = (0.3, -0.2, 0.5)
    F = [ed.solve(transforms=[T] * len(handles), warm_start=False, max_iterations=k).energy
         for k in range(1, 6)]
    assert F[-1] <= 1e-20, F
    for before, after in zip(F[1:], F[2:]):     # past the first, long steps
        assert after <= max(10.0 * before ** 2, 1e-20), F


def test_bumpy_plane_figure_3():
    """Left edge fixed, right edge lifted: a purely translational edit. Gauss-Newton converges
    by eq. 12 (all three tests, as in Gill et al.; the paper reports about six iterations, we
    take 18: Gauss-Newton converges linearly on this problem, and the gradient test alone
    stopped with the surface still 3% of its size from the minimum) to within 1e-4 of a
    tightly converged solve; the handles meet their targets within 1% of the drag, and the
    bumps keep their shape: each bump's region is a rigid motion of its rest shape to within
    a few % of the bump's height (no shearing)."""
    v, f, centres = bumpy_plane(200)      # 40,401 vertices and ~300 nodes, as in the paper
    fixed = np.where(v[:, 0] <= 1e-9)[0]
    handle = np.where(v[:, 0] >= 1 - 1e-9)[0]
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=300)
    lift = 0.4
    r = ed.solve(v[handle] + [0, 0, lift], warm_start=False)
    assert r.converged and 2 <= r.iterations <= 30, r.iterations
    tight = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=300,
                                   tolerance=1e-12, max_iterations=200)
    rt = tight.solve(v[handle] + [0, 0, lift], warm_start=False)
    assert np.abs(np.asarray(r.positions) - rt.positions).max() <= 1e-4
    err = np.abs(r.positions[handle] - (v[handle] + [0, 0, lift])).max()
    assert err <= 0.01 * lift, err
    assert np.abs(r.positions[fixed] - v[fixed]).max() == 0.0
    x = np.asarray(r.positions)
    for cx, cy in centres:
        near = np.where((v[:, 0] - cx) ** 2 + (v[:, 1] - cy) ** 2 < 0.06 ** 2)[0]
        assert kabsch_rms(v[near], x[near]) <= 0.1 * 0.04, (cx, cy)


def test_fixed_nodes_are_constants():
    v, f, _ = bumpy_plane(30)
    fixed = np.where(v[:, 0] <= 0.3)[0]
    handle = np.where(v[:, 0] >= 1 - 1e-9)[0]
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=100)
    ed.solve(v[handle] + [0, 0, 0.3], warm_start=False)
    const = np.array(ed.fixed_nodes)
    assert const.any() and not const.all()
    assert ed.stats["n_unknowns"] == 12 * int((~const).sum())
    X = ed.transforms[const]
    assert np.array_equal(X[:, :9], np.tile(np.eye(3).ravel(), (len(X), 1)))
    assert np.array_equal(X[:, 9:], np.zeros((len(X), 3)))
    # a fixed vertex's nodes are all constants: it stays exactly in place
    r = ed.solve(v[handle] + [0, 0, 0.3])
    assert np.array_equal(np.asarray(r.positions)[fixed], v[fixed])


def test_several_components_and_a_soup():
    a, fa = make_icosphere(2)
    b = a + [3.0, 0.0, 0.0]
    v = np.vstack([a, b])
    f = np.vstack([fa, fa + len(a)])
    handle = np.where(v[:, 0] > 3.8)[0]              # on the second sphere
    fixed = np.where(v[:, 0] < -0.5)[0]              # on the first
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=120)
    r = ed.solve(v[handle] + [0.5, 0, 0], warm_start=False)
    x = np.asarray(r.positions)
    assert np.abs(x[handle] - (v[handle] + [0.5, 0, 0])).max() < 0.05
    assert np.array_equal(x[fixed], v[fixed])
    # a polygon soup: every triangle on its own vertices
    soup_v = v[f.ravel()]
    soup_f = np.arange(len(soup_v)).reshape(-1, 3)
    hs = np.where(soup_v[:, 0] > 3.8)[0]
    ed = dk.EmbeddedDeformation(dk.Mesh(soup_v, soup_f), handles=[hs], n_nodes=120)
    r = ed.solve(soup_v[hs] + [0.5, 0, 0], warm_start=False)
    assert np.abs(np.asarray(r.positions)[hs] - (soup_v[hs] + [0.5, 0, 0])).max() < 0.05


def test_point_set():
    """A point cloud (no faces) deforms; its nodes come from its points."""
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 1, (3000, 2))
    v = np.c_[u, 0.05 * np.sin(6 * u[:, 0])]
    fixed, handle = np.where(v[:, 0] < 0.05)[0], np.where(v[:, 0] > 0.95)[0]
    mesh = dk.Mesh(v, np.zeros((0, 3), dtype=np.int32))
    ed = dk.EmbeddedDeformation(mesh, handles=[handle], fixed=fixed, n_nodes=100)
    assert all(np.abs(v - p).sum(axis=1).min() == 0.0 for p in ed.nodes)
    r = ed.solve(v[handle] + [0, 0, 0.3], warm_start=False)
    x = np.asarray(r.positions)
    assert np.abs(x[handle] - (v[handle] + [0, 0, 0.3])).max() < 0.01 * 0.3 * 3
    assert np.array_equal(x[fixed], v[fixed])
    mid = np.where(np.abs(v[:, 0] - 0.5) < 0.05)[0]
    assert 0.05 < np.median(x[mid, 2] - v[mid, 2]) < 0.25   # the middle follows part way


def test_bad_input():
    v, f = make_icosphere(2)
    mesh = dk.Mesh(v, f)
    with pytest.raises(ValueError, match="n_nodes"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=0)
    with pytest.raises(ValueError, match="k"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=3, k=4)
    with pytest.raises(ValueError, match="k must"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], k=17)
    with pytest.raises(ValueError, match="w_rot"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], w_rot=-1.0)
    with pytest.raises(ValueError, match="nothing can move"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], fixed=np.arange(1, len(v)))
    with pytest.raises(ValueError, match="nodes"):
        dk.EmbeddedDeformation(mesh, handles=[[0]], nodes="volume")
    ed = dk.EmbeddedDeformation(mesh, handles=[[0]], n_nodes=30)
    with pytest.raises(ValueError):
        ed.solve([[np.nan, 0.0, 0.0]])


def test_normals_follow_the_transformations():
    """eq. 3: the rest normals before any solve; a rigid motion rotates them (to the solver's
    convergence of the node rotations); given normals are used as given."""
    v, f = make_icosphere(3)
    mesh = dk.Mesh(v, f)
    caps = [np.where(v[:, 2] < -0.6)[0], np.where(v[:, 2] > 0.6)[0]]
    ed = dk.EmbeddedDeformation(mesh, handles=caps, n_nodes=100, tolerance=1e-12,
                                max_iterations=100)
    rest = ed.normals()
    assert np.allclose(np.linalg.norm(rest, axis=1), 1.0)
    assert np.all(np.sum(rest * v, axis=1) > 0.99)        # a sphere's normals are radial
    a = 0.9
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    T = np.eye(4)
    T[:3, :3] = R
    ed.solve(transforms=[T, T], warm_start=False)
    assert np.abs(ed.normals() - rest @ R.T).max() <= 1e-6
    given = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    assert np.abs(ed.normals(given) - given @ R.T).max() <= 1e-6


def test_embed_new_points():
    """Any points can be embedded: the mesh's own vertices get back exactly the solve's
    result, and points off the surface move with the graph."""
    v, f, _ = bumpy_plane(30)
    fixed = np.where(v[:, 0] <= 1e-9)[0]
    handle = np.where(v[:, 0] >= 1 - 1e-9)[0]
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=80)
    r = ed.solve(v[handle] + [0, 0, 0.3], warm_start=False)
    nodes, w, moved = ed.embed(v)
    assert nodes.shape == (len(v), 4) and w.shape == (len(v), 4)
    assert np.allclose(np.where(nodes >= 0, w, 0).sum(axis=1), 1.0)
    assert np.abs(moved - np.asarray(r.positions)).max() <= 1e-12
    above = v[handle] + [0, 0, 0.05]                       # points in space near the handle
    _, _, up = ed.embed(above)
    assert np.abs((up - above)[:, 2] - 0.3).max() < 0.05
    with pytest.raises(ValueError):
        ed.embed([[np.nan, 0, 0]])


def test_normals_use_the_inverse_transpose():
    """Under a stretch (every node the same affine map A, reached with a tiny w_rot), the
    normals are A^-T n renormalised: perpendicular to the stretched surface, unlike A n."""
    v, f = make_icosphere(3)
    mesh = dk.Mesh(v, f)
    caps = [np.where(v[:, 2] < -0.6)[0], np.where(v[:, 2] > 0.6)[0]]
    ed = dk.EmbeddedDeformation(mesh, handles=caps, n_nodes=100, w_rot=1e-9,
                                tolerance=1e-14, max_iterations=200)
    A = np.diag([2.0, 1.0, 0.5])
    T = np.eye(4)
    T[:3, :3] = A
    r = ed.solve(transforms=[T, T], warm_start=False)
    assert np.abs(np.asarray(r.positions) - v @ A.T).max() < 1e-3
    rest = v / np.linalg.norm(v, axis=1)[:, None]
    want = rest @ np.linalg.inv(A)          # (A^-T n) as rows: n^T A^-1
    want /= np.linalg.norm(want, axis=1)[:, None]
    assert np.abs(ed.normals(rest) - want).max() < 1e-3
    wrong = rest @ A.T
    wrong /= np.linalg.norm(wrong, axis=1)[:, None]
    assert np.abs(ed.normals(rest) - wrong).max() > 0.1


def test_deformed_repeats_the_solve():
    v, f, _ = bumpy_plane(20)
    handle = np.where(v[:, 0] >= 1 - 1e-9)[0]
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], n_nodes=40)
    assert np.abs(ed.deformed() - v).max() <= 1e-12         # identity before any solve
    r = ed.solve(v[handle] + [0, 0, 0.2], warm_start=False)
    assert np.array_equal(ed.deformed(), r.positions)


def hairpin(step=0.05, arm=4.0, width=0.5, gap=0.2):
    """A strip folded into a hairpin: the lower arm (the "leg", z = 0) and the upper arm (the
    "hand", z = gap) run side by side, a gap apart, and meet only through the bend at x = arm.
    Returns vertices, faces and each vertex's arc length s along the strip."""
    r = gap / 2
    length = 2 * arm + np.pi * r
    ns, nw = int(round(length / step)) + 1, int(round(width / step)) + 1
    s = np.linspace(0, length, ns)
    x = np.where(s <= arm, s, np.where(s >= arm + np.pi * r, 2 * arm + np.pi * r - s,
                                       arm + r * np.sin((s - arm) / r)))
    z = np.where(s <= arm, 0.0, np.where(s >= arm + np.pi * r, gap,
                                         r - r * np.cos((s - arm) / r)))
    y = np.linspace(0, width, nw)
    v = np.array([(x[i], y[j], z[i]) for i in range(ns) for j in range(nw)])
    arc = np.repeat(s, nw)
    faces = []
    for i in range(ns - 1):
        for j in range(nw - 1):
            a, b = i * nw + j, (i + 1) * nw + j
            faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    return v, np.array(faces), arc


def test_geodesic_influence_keeps_the_hand_off_the_leg():
    """Section 7: a hand lying next to the leg. In Euclidean distance the nodes at the hand's
    tip also move the leg below it (a gap of 0.2, nodes ~0.3 apart); along the surface the leg
    is 8 units away from the hand's tip, so it stays put."""
    v, f, s = hairpin()
    arm = 4.0
    leg_tip, hand_tip = np.where(s < 0.5)[0], np.where(s > s.max() - 0.25)[0]
    bend = np.where(np.abs(s - (arm + 0.16)) < 0.6)[0]          # fixed: the bend
    lift = 0.5
    moved, crossing = {}, {}     # crossing: graph edges across the gap, away from the bend
    for distance in ("euclidean", "geodesic"):
        ed = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[hand_tip], fixed=bend,
                                    n_nodes=120, distance=distance)
        r = ed.solve(v[hand_tip] + [0, 0, lift], warm_start=False)
        x = np.asarray(r.positions)
        assert np.abs(x[hand_tip, 2] - v[hand_tip, 2] - lift).max() < 0.02 * lift
        moved[distance] = np.abs(x[leg_tip] - v[leg_tip]).max()
        g, e = np.asarray(ed.nodes), np.asarray(ed.edges)
        crossing[distance] = int(np.sum((np.abs(g[e[:, 0], 2] - g[e[:, 1], 2]) > 0.19)
                                        & (g[e[:, 0], 0] < arm - 0.5) & (g[e[:, 1], 0] < arm - 0.5)))
    assert moved["euclidean"] > 0.2 * lift       # the leg follows the hand
    assert moved["geodesic"] < 1e-3 * lift       # it does not
    assert crossing["euclidean"] > 0 and crossing["geodesic"] == 0
    # a point set has no surface to measure along
    with pytest.raises(ValueError, match="geodesic"):
        dk.EmbeddedDeformation(dk.Mesh(v, np.zeros((0, 3), dtype=np.int32)),
                               handles=[hand_tip], distance="geodesic")
    with pytest.raises(ValueError, match="distance"):
        dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[hand_tip], distance="manhattan")


def test_cut_separates_the_hand_from_the_leg():
    """Section 7's stroke, as two vertex groups: in Euclidean distance, a cut between the
    hairpin's arms keeps the hand's nodes off the leg (as geodesic influence does) and leaves
    no graph edge between the two sides; without it the leg follows."""
    v, f, s = hairpin()
    arm, r = 4.0, 0.1
    leg_tip, hand_tip = np.where(s < 0.5)[0], np.where(s > s.max() - 0.25)[0]
    bend = np.where(np.abs(s - (arm + 0.16)) < 0.6)[0]
    leg, hand = np.where(s < arm - 0.3)[0], np.where(s > arm + np.pi * r + 0.3)[0]
    mesh = dk.Mesh(v, f)
    target = v[hand_tip] + [0, 0, 0.5]
    plain = dk.EmbeddedDeformation(mesh, handles=[hand_tip], fixed=bend, n_nodes=120)
    cut = dk.EmbeddedDeformation(mesh, handles=[hand_tip], fixed=bend, n_nodes=120,
                                 cut=(leg, hand))
    moved = {}
    for name, ed in (("plain", plain), ("cut", cut)):
        x = np.asarray(ed.solve(target, warm_start=False).positions)
        assert np.abs(x[hand_tip, 2] - target[:, 2]).max() < 0.02 * 0.5
        moved[name] = np.abs(x[leg_tip] - v[leg_tip]).max()
    assert moved["plain"] > 0.1 and moved["cut"] < 1e-3 * 0.5
    # no edge joins a node nearest to the leg group with one nearest to the hand group
    g = np.asarray(cut.nodes)
    near = np.argmin(np.linalg.norm(g[:, None] - v[None], axis=2), axis=1)
    side = np.zeros(len(v), int)
    side[leg], side[hand] = 1, 2
    e = np.asarray(cut.edges)
    a, b = side[near[e[:, 0]]], side[near[e[:, 1]]]
    assert not np.any((a * b == 2))
    # the cut reaches geodesic influence too, and bad cuts are refused by name
    dk.EmbeddedDeformation(mesh, handles=[hand_tip], n_nodes=120, distance="geodesic",
                           cut=(leg, hand))
    with pytest.raises(ValueError, match="both cut groups"):
        dk.EmbeddedDeformation(mesh, handles=[hand_tip], cut=(leg, leg[:5]))
    with pytest.raises(ValueError, match="cut group B is empty"):
        dk.EmbeddedDeformation(mesh, handles=[hand_tip], cut=(leg, []))
    with pytest.raises(ValueError, match="pair"):
        dk.EmbeddedDeformation(mesh, handles=[hand_tip], cut=leg)
    with pytest.raises(IndexError, match="cut group B"):
        dk.EmbeddedDeformation(mesh, handles=[hand_tip], cut=(leg, [len(v)]))
    with pytest.raises(ValueError, match="cut leaves"):
        dk.EmbeddedDeformation(mesh, handles=[hand_tip], n_nodes=8, cut=(leg, hand))


def test_update_source_follows_an_animated_mesh():
    """Section 5: a graph on vertices rides along the source. After update_source(P), the
    object solves what a fresh bind on P (same graph: same radius) solves; a translated source
    with translated targets gives the translated result; going back to the rest gives the
    first result again, bit for bit; bad positions are refused and change nothing; surface
    samples keep their places in their triangles. (A rotated source is compared with a fresh bind, not with the rotated
    first result: eq. 6 counts each off-diagonal entry of R^T R once, so E_rot, and a
    non-rigid result, depend on the orientation in space.)"""
    v, f, _ = bumpy_plane(30)
    fixed = np.where(v[:, 0] <= 1e-9)[0]
    handle = np.where(v[:, 0] >= 1 - 1e-9)[0]
    # jittered, so that no two nodes tie for a vertex (a tie is broken by rounding, which
    # differs between the two frames)
    v = v + np.c_[np.random.default_rng(5).uniform(-0.004, 0.004, (len(v), 2)), np.zeros(len(v))]
    opts = dict(handles=[handle], fixed=fixed, radius=0.12, nodes="vertices")
    ed = dk.EmbeddedDeformation(dk.Mesh(v, f), **opts)
    target = v[handle] + [0.0, 0.0, 0.3]
    first = np.array(ed.solve(target, warm_start=False).positions)
    c, s = np.cos(0.7), np.sin(0.7)
    q = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, s],
                                                                 [0, -s, c]])
    vr = v @ q.T + [0.3, -1.0, 2.0]
    ed.update_source(vr)
    assert np.abs(np.asarray(ed.nodes) - vr[np.argmin(
        np.linalg.norm(vr[None] - np.asarray(ed.nodes)[:, None], axis=2), axis=1)]).max() == 0
    tr = vr[handle] + (target - v[handle]) @ q.T
    moved = np.array(ed.solve(tr, warm_start=False).positions)
    fresh = dk.EmbeddedDeformation(dk.Mesh(vr, f), **opts)
    assert len(fresh.nodes) == len(ed.nodes)
    want = np.array(fresh.solve(tr, warm_start=False).positions)
    assert np.abs(moved - want).max() < 1e-8
    assert np.array_equal(moved[fixed], vr[fixed])                      # fixed ride along
    assert np.abs(moved - (first @ q.T + [0.3, -1.0, 2.0])).max() > 1e-6  # eq. 6, see above
    # a translated frame with the same offsets: the translated result
    ed.update_source(v + [0, 0, 1.0])
    r = np.array(ed.solve(target + [0, 0, 1.0], warm_start=False).positions)
    assert np.abs(r - (first + [0, 0, 1.0])).max() < 1e-8
    ed.update_source(v)
    again = np.array(ed.solve(target, warm_start=False).positions)
    assert np.array_equal(again, first)
    with pytest.raises(ValueError, match="positions"):
        ed.update_source(v[:-1])
    bad = v.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError):
        ed.update_source(bad)
    assert np.array_equal(np.array(ed.solve(target, warm_start=False).positions), first)
    surf = dk.EmbeddedDeformation(dk.Mesh(v, f), handles=[handle], fixed=fixed, n_nodes=80)
    g0 = np.array(surf.nodes)
    # a smooth non-rigid motion of the source: every node stays on the moved surface, at
    # the same barycentric place (so a node's image is the map of the node, up to the
    # map's curvature inside one triangle)
    bend = lambda x: np.c_[x[:, 0], x[:, 1], x[:, 2] + 0.5 * x[:, 0] ** 2]
    surf.update_source(bend(v))
    g1 = np.array(surf.nodes)
    assert np.abs(g1 - bend(g0)).max() < 0.5 * (1 / 29) ** 2
    assert np.abs(g1 - g0).max() > 0.1
    first = np.array(surf.solve(bend(v)[handle]).positions)    # no motion: the new source
    assert np.abs(first - bend(v)).max() < 1e-12


def test_a_graph_denser_than_its_mesh_is_warned_of():
    """A radius that puts more nodes than vertices on a small grid makes a floppy graph
    (docs/methods/embedded.md, "Edges"): translating both ends leaves inner vertices behind at
    a small energy. The object says so in `warnings`; the default graph (capped at the vertex
    count) is exact and says nothing."""
    v, f = make_grid(5, 4, bump=0.15, jitter=0.3, seed=3)
    left, right = np.where(v[:, 0] <= 1e-9)[0], np.where(v[:, 0] >= 1 - 1e-9)[0]
    t = np.array([0.3, 0.2, 0.1])
    targets = np.vstack([v[left] + t, v[right] + t])
    mesh = dk.Mesh(v, f)
    ok = dk.EmbeddedDeformation(mesh, handles=[left, right])
    assert len(ok.nodes) <= len(v) and ok.warnings == ()
    assert np.abs(np.asarray(ok.solve(targets).positions) - v - t).max() < 1e-9
    dense = dk.EmbeddedDeformation(mesh, handles=[left, right], radius=0.05)
    lag = np.abs(np.asarray(dense.solve(targets).positions) - v - t).max()
    assert len(dense.nodes) > len(v) and lag > 1e-3 * np.linalg.norm(t)  # the floppiness
    (w,) = dense.warnings
    assert "has %d nodes for %d vertices" % (len(dense.nodes), len(v)) in w and "fewer" in w


def test_rebind_resets_the_nodes_that_become_constant():
    """After rebind(fixed=larger), the nodes the new fixed set makes constant are the
    identity: a warm solve blended the last solve's transforms of them into the vertices
    near the new fixed part."""
    v, f = make_grid(20, 10, bump=0.1, jitter=0.2)
    mesh = dk.Mesh(v, f)
    left = np.where(v[:, 0] <= 0.05)[0]
    wider = np.where(v[:, 0] <= 0.5)[0]
    right = np.where(v[:, 0] >= 0.95)[0]
    target = v[right] + [0.0, 0.3, 0.4]
    ed = dk.EmbeddedDeformation(mesh, [right], fixed=left)
    ed.solve(target)
    ed.rebind(fixed=wider)
    got = np.asarray(ed.solve(target).positions)
    fresh = np.asarray(dk.EmbeddedDeformation(mesh, [right], fixed=wider).solve(target).positions)
    assert np.abs(got - fresh).max() < 1e-3 * np.ptp(v, axis=0).max()

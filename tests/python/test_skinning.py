"""deformkit.Skinning (docs/methods/skinning.md) with given weights: linear blend skinning
against the slides' formula in numpy, dual quaternion skinning against an independent numpy
blend of unit dual quaternions; a bone's own motion where its weight is 1, a motion shared by
every bone reproduced, the candy wrapper (a half-turn twist collapses the linear blend and not
the dual quaternions), an input pose skinned, scale and placement, refusals. Matching Blender's
Armature modifier (both blends) is tests/blender/test_addon_controls.py."""
import numpy as np
import pytest

import deformkit as dk


def cylinder(n_ring=24, n_len=41, radius=0.2):
    th = np.linspace(0, 2 * np.pi, n_ring, endpoint=False)
    xs = np.linspace(-1, 1, n_len)
    V = np.array([(x, radius * np.cos(t), radius * np.sin(t)) for x in xs for t in th])
    F = []
    for i in range(n_len - 1):
        for j in range(n_ring):
            a, b = i * n_ring + j, i * n_ring + (j + 1) % n_ring
            F += [[a, a + n_ring, b], [b, a + n_ring, b + n_ring]]
    return V, np.array(F)


def rot(axis, a):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def frame(R=np.eye(3), t=(0, 0, 0), scale=1.0):
    F = np.eye(4)
    F[:3, :3] = scale * R
    F[:3, 3] = t
    return F


def two_bones(V):
    B = np.array([frame(t=(-1.0, 0, 0)), frame(t=(0.0, 0, 0))])
    w = np.clip(0.5 + V[:, 0] / 0.4, 0.0, 1.0)
    return B, np.c_[1 - w, w]


def quat(R):
    """Rotation matrix -> unit quaternion (w, x, y, z), numpy, via the eigenvector of the
    symmetric 4 x 4 (Bar-Itzhack): independent of the native Shepperd's."""
    K = np.array([[R[0, 0] - R[1, 1] - R[2, 2], R[1, 0] + R[0, 1], R[2, 0] + R[0, 2],
                   R[2, 1] - R[1, 2]],
                  [R[1, 0] + R[0, 1], R[1, 1] - R[0, 0] - R[2, 2], R[2, 1] + R[1, 2],
                   R[0, 2] - R[2, 0]],
                  [R[2, 0] + R[0, 2], R[2, 1] + R[1, 2], R[2, 2] - R[0, 0] - R[1, 1],
                   R[1, 0] - R[0, 1]],
                  [R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1],
                   R[0, 0] + R[1, 1] + R[2, 2]]]) / 3.0
    w, v = np.linalg.eigh(K)
    q = v[:, np.argmax(w)]
    return np.array([q[3], q[0], q[1], q[2]])


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def dqs_numpy(V, B, T, W):
    """Dual quaternion skinning, written from Kavan et al. with numpy: rigid parts by polar
    decomposition (SVD), dual quaternions on the heaviest bone's side, stretches linear."""
    M = [t @ np.linalg.inv(b) for t, b in zip(T, B)]
    parts = []
    for m in M:
        U, s, Vt = np.linalg.svd(m[:3, :3])
        R = U @ Vt
        S = R.T @ m[:3, :3]
        r = quat(R)
        d = 0.5 * qmul(np.r_[0.0, m[:3, 3]], r)
        parts.append((r, d, S))
    out = np.empty_like(V)
    for i, p in enumerate(V):
        piv = parts[int(np.argmax(W[i]))][0]
        r, d, S = np.zeros(4), np.zeros(4), np.zeros((3, 3))
        for j, (rj, dj, Sj) in enumerate(parts):
            sgn = -1.0 if rj @ piv < 0 else 1.0
            r += sgn * W[i, j] * rj
            d += sgn * W[i, j] * dj
            S += W[i, j] * Sj
        n = np.linalg.norm(r)
        r, d = r / n, d / n
        q = S @ p
        rq = qmul(qmul(r, np.r_[0.0, q]), r * [1, -1, -1, -1])[1:]
        t = 2 * qmul(d, r * [1, -1, -1, -1])[1:]
        out[i] = rq + t
    return out


def test_linear_blend_is_the_slides_formula():
    V, F = cylinder()
    B, W = two_bones(V)
    rng = np.random.default_rng(3)
    W = np.c_[W, rng.uniform(0, 0.3, len(V))]
    W /= W.sum(axis=1, keepdims=True)
    B = np.r_[B, frame(rot((0, 1, 1), 0.4), (0.3, 0.2, -0.1))[None]]
    T = np.array([frame(rot((0, 0, 1), 0.5), (-0.9, 0.1, 0)), frame(rot((1, 1, 0), 1.1),
                  (0.2, 0.3, 0.1), 1.3), frame(rot((1, 0, 0), -0.7), (0.1, 0, 0.4))])
    s = dk.Skinning(dk.Mesh(V, F), bone_frames=B, weights=W)
    got = np.asarray(s.solve(transforms=T).positions)
    Vh = np.c_[V, np.ones(len(V))]
    want = sum(W[:, [j]] * (Vh @ (T[j] @ np.linalg.inv(B[j])).T)[:, :3] for j in range(3))
    assert np.abs(got - want).max() < 1e-12
    assert np.array_equal(np.asarray(s.solve(transforms=B).positions), V)
    np.testing.assert_array_equal(s.rest_frames, B)


def test_dual_quaternions_against_numpy():
    V, F = cylinder(n_ring=12, n_len=21)
    B, W = two_bones(V)
    T = np.array([frame(rot((0, 0, 1), 0.3), (-1.0, 0.1, 0)),
                  frame(rot((1, 0.2, 0), 2.4), (0.1, 0.0, 0.2))])
    s = dk.Skinning(dk.Mesh(V, F), bone_frames=B, weights=W, blend="dual_quaternion")
    got = np.asarray(s.solve(transforms=T).positions)
    assert np.abs(got - dqs_numpy(V, B, T, W)).max() < 1e-12
    # with a stretch (one bone scaled by 1.4 and sheared)
    T[1, :3, :3] = T[1, :3, :3] @ np.array([[1.4, 0.2, 0], [0, 1.0, 0], [0, 0, 0.9]])
    got = np.asarray(s.solve(transforms=T).positions)
    assert np.abs(got - dqs_numpy(V, B, T, W)).max() < 1e-12
    assert np.array_equal(np.asarray(s.solve(transforms=B).positions), V)


@pytest.mark.parametrize("blend", ["linear", "dual_quaternion"])
def test_own_and_shared_motions(blend):
    V, F = cylinder()
    B, W = two_bones(V)
    s = dk.Skinning(dk.Mesh(V, F), bone_frames=B, weights=W, blend=blend)
    T = np.array([frame(rot((0, 1, 0), 0.6), (-1.0, 0.2, 0.1)),
                  frame(rot((0, 0, 1), 1.9), (0.3, -0.1, 0.5))])
    x = np.asarray(s.solve(transforms=T).positions)
    for j in range(2):
        only = W[:, j] == 1.0
        M = T[j] @ np.linalg.inv(B[j])
        assert np.abs(x[only] - (V[only] @ M[:3, :3].T + M[:3, 3])).max() < 1e-12
    # every bone moved alike (a rotation, a uniform scale and a move): the mesh by it
    G = frame(rot((1, 2, 3), 0.8), (0.4, -0.3, 0.2), 1.5)
    x = np.asarray(s.solve(transforms=np.array([G @ b for b in B])).positions)
    assert np.abs(x - (V @ G[:3, :3].T + G[:3, 3])).max() < 1e-12


def test_the_candy_wrapper():
    """Half a turn of twist on the lower bone: the linear blend pinches the middle to its
    axis, the dual quaternions keep its girth."""
    V, F = cylinder()
    B, W = two_bones(V)
    T = B.copy()
    T[1, :3, :3] = rot((1, 0, 0), np.pi)
    mid = np.abs(V[:, 0]) < 1e-9
    girth = {}
    for blend in ("linear", "dual_quaternion"):
        s = dk.Skinning(dk.Mesh(V, F), bone_frames=B, weights=W, blend=blend)
        x = np.asarray(s.solve(transforms=T).positions)
        girth[blend] = np.linalg.norm(x[mid][:, 1:], axis=1).min()
    assert girth["linear"] < 1e-12 and abs(girth["dual_quaternion"] - 0.2) < 1e-12, girth


@pytest.mark.parametrize("blend", ["linear", "dual_quaternion"])
def test_input_pose_scale_and_placement(blend):
    V, F = cylinder(n_ring=12, n_len=21)
    B, W = two_bones(V)
    T = np.array([frame(rot((0, 1, 0), 0.4), (-1.0, 0, 0)), frame(rot((0, 0, 1), 1.2),
                  (0.1, 0.2, 0))])
    s = dk.Skinning(dk.Mesh(V, F), bone_frames=B, weights=W, blend=blend)
    pose = V + 0.01 * np.cos(7 * V)
    a = np.asarray(s.solve(transforms=T, input_positions=pose).positions)
    s2 = dk.Skinning(dk.Mesh(pose, F), bone_frames=B, weights=W, blend=blend)
    assert np.abs(a - np.asarray(s2.solve(transforms=T).positions)).max() < 1e-13
    x1 = np.asarray(s.solve(transforms=T).positions)
    k, off = 1000.0, np.array([3e3, -1e3, 5e2])
    S = frame(scale=k, t=off)
    s3 = dk.Skinning(dk.Mesh(V * k + off, F), bone_frames=np.array([S @ b for b in B]),
                     weights=W, blend=blend)
    x3 = np.asarray(s3.solve(transforms=np.array([S @ t for t in T])).positions)
    assert np.abs((x3 - off) / k - x1).max() < 1e-11


def test_refusals():
    V, F = cylinder(n_ring=8, n_len=5)
    B, W = two_bones(V)
    mesh = dk.Mesh(V, F)
    with pytest.raises(ValueError, match="sum"):
        dk.Skinning(mesh, bone_frames=B, weights=W * 0.5)
    with pytest.raises(ValueError):
        dk.Skinning(mesh, bone_frames=B, weights=-W)
    Bs = B.copy()
    Bs[1, 2, :3] = 0.0
    with pytest.raises(ValueError):
        dk.Skinning(mesh, bone_frames=Bs, weights=W)
    with pytest.raises(ValueError, match="blend"):
        dk.Skinning(mesh, bone_frames=B, weights=W, blend="spherical")
    s = dk.Skinning(mesh, bone_frames=B, weights=W)
    T = B.copy()
    T[0, 3, 0] = 0.5
    with pytest.raises(ValueError, match="affine"):
        s.solve(transforms=T)
    with pytest.raises(TypeError, match="frames"):
        s.solve(np.zeros((2, 3)))
    # arrays of blocks in another layout are refused by name, not read in another order
    bones = np.array([[[-1.0, 0, 0], [0.0, 0, 0]], [[0.0, 0, 0], [1.0, 0, 0]]])
    a = dk.Skinning(mesh, bone_frames=B, bones=bones)
    b = dk.Skinning(mesh, bone_frames=B.reshape(2, 16), bones=bones.reshape(2, 6))
    np.testing.assert_array_equal(a.solve(transforms=B).positions, b.solve(transforms=B).positions)
    with pytest.raises(ValueError, match=r"bones: expected k x 2 x 3.* 3 x 2"):
        dk.Skinning(mesh, bone_frames=B, bones=bones.transpose(0, 2, 1))
    with pytest.raises(ValueError, match=r"bone_frames: expected k x 4 x 4"):
        dk.Skinning(mesh, bone_frames=B[:, :, :2], weights=W)
    with pytest.raises(ValueError, match=r"bones: expected k x 2 x 3"):
        dk.bounded_biharmonic_weights(mesh, bones=bones.transpose(0, 2, 1))
    with pytest.raises(ValueError, match=r"transforms: expected k x 4 x 4"):
        s.solve(transforms=np.zeros((4, 2, 8)))

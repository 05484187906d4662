"""Test shapes in plain numpy, shared by the Python suites and the Blender ones
(tests/blender/_setup.py puts this folder on the path)."""
import numpy as np


def capped_tube(n_ring=16, n_len=21, radius=0.2, length=2.0):
    """A closed tube along x from -length/2 to length/2, `n_len` rings of `n_ring` vertices,
    fans closing both ends about a centre vertex each (the last two vertices)."""
    th = np.linspace(0, 2 * np.pi, n_ring, endpoint=False)
    xs = np.linspace(-length / 2, length / 2, n_len)
    V = [(x, radius * np.cos(t), radius * np.sin(t)) for x in xs for t in th]
    F = []
    for i in range(n_len - 1):
        for j in range(n_ring):
            a, b = i * n_ring + j, i * n_ring + (j + 1) % n_ring
            F += [[a, b, a + n_ring], [b, b + n_ring, a + n_ring]]
    c0, c1 = len(V), len(V) + 1
    V += [(xs[0], 0, 0), (xs[-1], 0, 0)]
    last = (n_len - 1) * n_ring
    for j in range(n_ring):
        F += [[c0, (j + 1) % n_ring, j], [c1, last + j, last + (j + 1) % n_ring]]
    return np.array(V), np.array(F)


def twist(V, turn, axis=0, about=(0.0, 0.0, 0.0)):
    """V twisted about the line through `about` along coordinate `axis` by up to `turn`
    radians, growing linearly from V's lowest point along the axis (0) to its highest."""
    h = (V[:, axis] - V[:, axis].min()) / np.ptp(V[:, axis])
    t = h * turn
    a, b = [k for k in range(3) if k != axis]
    c = np.asarray(about, dtype=float)
    out = V.copy()
    out[:, a] = c[a] + np.cos(t) * (V[:, a] - c[a]) - np.sin(t) * (V[:, b] - c[b])
    out[:, b] = c[b] + np.sin(t) * (V[:, a] - c[a]) + np.cos(t) * (V[:, b] - c[b])
    return out


def bend(V, angle, start=-0.5, length=1.0):
    """A mesh along x bent about z towards +y by `angle` over x in [start, start + length]
    (its centre line on a circular arc, unstretched; the inside compressed and the outside
    stretched as a bent elbow's): an arm."""
    x, y = V[:, 0], V[:, 1]
    rho = length / angle
    phi = angle * np.clip((x - start) / length, 0, 1)
    past = np.maximum(x - start - length, 0.0)
    out = V.copy()
    out[:, 0] = np.where(x < start, x, start + (rho - y) * np.sin(phi) + past * np.cos(phi))
    out[:, 1] = np.where(x < start, y, rho - (rho - y) * np.cos(phi) + past * np.sin(phi))
    return out


def volume(X, F):
    """The volume a closed triangle mesh encloses (signed, outward faces positive)."""
    a, b, c = X[F[:, 0]], X[F[:, 1]], X[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def rigid_fit(X, Y):
    """(rms distance of Y from the rigid motion of X closest to it, that motion's R)."""
    cx, cy = X.mean(0), Y.mean(0)
    U, _, Vt = np.linalg.svd((X - cx).T @ (Y - cy))
    d = np.sign(np.linalg.det(U @ Vt))
    R = (U @ np.diag([1, 1, d]) @ Vt).T
    return float(np.sqrt((((X - cx) @ R.T + cy - Y) ** 2).sum(1).mean())), R


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

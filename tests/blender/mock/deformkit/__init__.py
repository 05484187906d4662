"""A stand-in for the native module with the same API shape, used only to develop and test the
add-on's plumbing before/without the native build (DEFORMKIT_MOCK=1 in tests). Handles move
rigidly, every other vertex stays at rest. Never shipped."""
import collections
import numpy as np

SolveResult = collections.namedtuple("SolveResult", "positions energy iterations converged")


class Mesh:
    def __init__(self, vertices, triangles):
        self.vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        self.triangles = np.asarray(triangles, dtype=np.int32).reshape(-1, 3)
        if len(self.triangles) == 0:
            raise ValueError("mesh has no triangles")
        self.n_vertices = len(self.vertices)


class _Method:
    def __init__(self, mesh, handles, fixed=None, roi=None, **kw):
        self.mesh = mesh
        self.rebind(handles, fixed, roi)

    def rebind(self, handles=None, fixed=None, roi=None):
        self.handles = [np.asarray(h, dtype=np.int64) for h in handles]
        allh = np.concatenate(self.handles)
        if fixed is not None:
            both = np.intersect1d(allh, np.asarray(fixed))
            if len(both):
                raise ValueError("vertex %d is both in a handle and fixed" % both[0])

    def solve(self, targets=None, transforms=None, **kw):
        p = self.mesh.vertices.copy()
        if transforms is not None:
            T = np.asarray(transforms, dtype=np.float64).reshape(-1, 4, 4)
            for h, t in zip(self.handles, T):
                p[h] = p[h] @ t[:3, :3].T + t[:3, 3]
        else:
            t = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
            p[np.concatenate(self.handles)] = t
        return SolveResult(p, 0.0, 1, True)


def _registry_classes():
    """One stand-in class per method of the add-on's registry (addon/methods.py, read by
    path: it needs no bpy), so that the mock never keeps a list of its own."""
    import importlib.util
    import os
    path = os.path.join(os.path.dirname(__file__), "..", "..", "..", "..", "addon", "methods.py")
    spec = importlib.util.spec_from_file_location("_deformkit_mock_registry", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return [m.native_class for m in mod.METHODS]


METHODS = tuple(_registry_classes())
globals().update({name: type(name, (_Method,), {}) for name in METHODS})

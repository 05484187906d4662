"""DeformKit: mesh deformation solvers (ARAP, Laplacian editing, falloff) for Blender.

The numerical work lives in the native extension ``deformkit._native`` (C11, CPython Limited
API 3.11, so one binary serves every Python >= 3.11, including Blender's). This package
re-exports everything public from it:

* ``Mesh`` (validated triangle mesh with topology), ``Mesh.from_polygons``,
  ``load_mesh_file`` / ``read_mesh`` for .obj/.off/.ply files;
* operators: ``uniform_laplacian``, ``cotangent_laplacian``, ``cotangent_weights``,
  ``mass_matrix``, ``geodesic_distance`` / ``HeatGeodesic``, ``laplacian_eigenpairs``,
  ``knn`` / ``KDTree``, ``closest_rotation``;
* deformation methods, one class each, named in ``METHODS``, whose ``solve`` returns a
  ``SolveResult``; they share one contract (docs/python-api.md, "The method contract").

Inputs are any buffer (numpy arrays, memoryviews, array.array) of float32/float64 or
int32/int64, or nested sequences; outputs are numpy arrays when numpy is importable.
See docs/python-api.md for the full contract.
"""

import os as _os

from . import _native

__version__ = "0.1.0"

__all__ = sorted(name for name in dir(_native) if not name.startswith("_"))

globals().update({name: getattr(_native, name) for name in __all__})

#: The deformation method classes' names, in the native registry's order.
METHODS = tuple(_native._methods)

__all__ += ["METHODS", "__version__"]

# A child forked from a process that used DeformKit (multiprocessing's "fork" start method)
# binds and solves like the parent: see _native._after_fork_in_child and docs/reliability.md
# (issue 18, class 3).
_os.register_at_fork(before=_native._before_fork,
                     after_in_parent=_native._after_fork_in_parent,
                     after_in_child=_native._after_fork_in_child)

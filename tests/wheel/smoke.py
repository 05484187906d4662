"""Smoke test of an installed or extracted `deformkit` native package, in a fresh Python:

    python -I tests/wheel/smoke.py [--path DIR] [--under DIR] [SYSTEM_COPY...]

--path DIR   put DIR first on sys.path (an extracted wheel or add-on folder)
--under DIR  the package must be imported from inside DIR
SYSTEM_COPY  files the bundled libraries were copied from: none may be loaded (nor any file
             named like a bundled library's original)

Runs small solves that reach each bundled native library (CHOLMOD and BLAS through ARAP and
Laplacian editing, ARPACK through the eigenpairs, LAPACKE through the closest rotation), then
reads /proc/self/maps: every library in the package's deformkit.libs/ must be mapped, and none
of the system copies. numpy is kept out, so that no other BLAS enters the process (outputs are
then memoryviews). Prints one line and exits 0 when all holds.
"""
import argparse
import os
import re
import sys

sys.modules["numpy"] = None

ap = argparse.ArgumentParser()
ap.add_argument("--path")
ap.add_argument("--under")
ap.add_argument("system_copies", nargs="*")
args = ap.parse_args()
if args.path:
    sys.path.insert(0, args.path)

import deformkit as dk  # noqa: E402

here = os.path.realpath(os.path.dirname(dk.__file__))
if args.under:
    assert here.startswith(os.path.realpath(args.under) + os.sep), (dk.__file__, args.under)

nx, ny = 8, 5
verts = [(i / (nx - 1), j / (ny - 1), 0.05 * ((i * j) % 3)) for j in range(ny) for i in range(nx)]
tris = []
for j in range(ny - 1):
    for i in range(nx - 1):
        a = j * nx + i
        tris += [(a, a + 1, a + nx + 1), (a, a + nx + 1, a + nx)]
mesh = dk.Mesh(verts, tris)
fixed = [j * nx for j in range(ny)]
handle = [j * nx + nx - 1 for j in range(ny)]
T = [[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1]]]
for cls in (dk.ARAP, dk.LaplacianEdit, dk.Falloff):
    p = cls(mesh, handles=[handle], fixed=fixed).solve(transforms=T).positions
    assert abs(p[handle[0], 2] - (verts[handle[0]][2] + 0.3)) < 1e-6, (cls, p[handle[0], 2])
    assert abs(p[fixed[0], 2] - verts[fixed[0]][2]) < 1e-9, cls
evals, evecs = dk.laplacian_eigenpairs(mesh, 3)
assert abs(evals[0]) < 1e-6 and evals[1] > 1e-3, list(evals)
R = dk.closest_rotation([[0, -2, 0], [2, 0, 0], [0, 0, 2]])
assert abs(R[0, 1] + 1) < 1e-9 and abs(R[1, 0] - 1) < 1e-9, R.tolist()

libs = os.path.join(os.path.dirname(here), "deformkit.libs")
bundled = sorted(f for f in os.listdir(libs) if ".so" in f)
assert bundled, "no libraries in " + libs
mapped = set()
with open("/proc/self/maps") as f:
    for line in f:
        parts = line.split(None, 5)
        if len(parts) == 6 and parts[5].startswith("/"):
            mapped.add(os.path.realpath(parts[5].strip()))
missing = [b for b in bundled if os.path.realpath(os.path.join(libs, b)) not in mapped]
assert not missing, "bundled libraries not loaded: %s" % missing
# by path (the copies named on the command line) and by name: auditwheel's names are the
# originals with a hash (libcholmod-7426373e.so.3.0.14 was libcholmod.so.3.0.14)
originals = {re.sub(r"-[0-9a-f]{8}(?=\.)", "", b) for b in bundled}
foreign = sorted((mapped & {os.path.realpath(p) for p in args.system_copies})
                 | {p for p in mapped if os.path.basename(p) in originals})
assert not foreign, "system copies of bundled libraries loaded: %s" % foreign
print("deformkit %s from %s: solves ok, %d bundled libraries mapped, no system copy"
      % (dk.__version__, here, len(bundled)))

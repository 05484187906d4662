"""Measures deformkit.ARAP on a shared scenario (default: armadillo-wave).

Prints: bind time; time per iteration (plain, from a fixed-count run); the converged energy
(long plain run, tolerance 1e-12); iterations and wall time for plain and Anderson solves to
come within 1% of it (cold start, capped runs); a warm-started re-solve after a small handle
move, run to the default tolerance.

    PYTHONPATH=build/python OPENBLAS_NUM_THREADS=1 /usr/bin/python3 scripts/measure_arap.py \
        [scenario.json] [--energy spokes|spokes_and_rims]
"""
import argparse
import json
import pathlib
import time

import numpy as np

import deformkit

ROOT = pathlib.Path(__file__).resolve().parents[1]
DEFAULT = ROOT / ".." / "shared" / "scenarios" / "armadillo-wave.json"


def read_obj(path):
    verts, faces = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
                for k in range(1, len(idx) - 1):
                    faces.append((idx[0], idx[k], idx[k + 1]))
    return np.array(verts), np.array(faces, dtype=np.int64)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", nargs="?", default=str(DEFAULT))
    ap.add_argument("--energy", default="spokes")
    args = ap.parse_args()
    sc_path = pathlib.Path(args.scenario)
    sc = json.loads(sc_path.read_text())
    v, f = read_obj(sc_path.parent / sc["mesh"])
    mesh = deformkit.Mesh(v, f)
    handles = [np.array(h["vertices"]) for h in sc["handles"]]
    targets = np.vstack([v[h] + h_["translate"] for h, h_ in zip(handles, sc["handles"])])
    fixed = np.array(sc["fixed"])
    print(f"{sc['name']}: {len(v)} vertices, {len(f)} triangles, energy={args.energy}")

    def bind(**kw):
        t0 = time.perf_counter()
        a = deformkit.ARAP(mesh, handles, fixed=fixed, energy=args.energy, **kw)
        return a, time.perf_counter() - t0

    binds = [bind()[1] for _ in range(3)]
    print(f"bind: {min(binds) * 1e3:.1f} ms (best of 3)")

    plain, _ = bind(acceleration="none", tolerance=0.0, max_iterations=2000)
    t0 = time.perf_counter()
    r = plain.solve(targets, warm_start=False, max_iterations=1)
    t1 = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = plain.solve(targets, warm_start=False, max_iterations=51)
    t51 = time.perf_counter() - t0
    print(f"plain iteration: {(t51 - t1) / 50 * 1e3:.2f} ms (incl. local step, energy, "
          f"3-RHS solve)")

    ref, _ = bind(acceleration="none", tolerance=1e-12, max_iterations=3000)
    t0 = time.perf_counter()
    rr = ref.solve(targets, warm_start=False)
    e_star = rr.energy
    print(f"converged energy (plain, {rr.iterations} iterations, tol 1e-12): {e_star:.9g} "
          f"({time.perf_counter() - t0:.1f} s)")
    acc, _ = bind(acceleration="anderson", tolerance=0.0, max_iterations=2000)
    for name, obj in (("plain", plain), ("anderson", acc)):
        k = 1
        while k <= 2000:
            t0 = time.perf_counter()
            r = obj.solve(targets, warm_start=False, max_iterations=k)
            dt = time.perf_counter() - t0
            if r.energy <= 1.01 * e_star:
                break
            k = k + 1 if k < 20 else int(k * 1.15) + 1
        print(f"{name}: within 1% of converged energy after {r.iterations} iterations, "
              f"{dt:.3f} s solve (+ bind)")
    default, _ = bind()
    t0 = time.perf_counter()
    r0 = default.solve(targets, warm_start=False)
    dt0 = time.perf_counter() - t0
    print(f"default options cold solve: {r0.iterations} iterations, {dt0:.3f} s, energy "
          f"{r0.energy:.9g} ({(r0.energy / e_star - 1) * 100:.3f}% above converged), "
          f"converged={r0.converged}")
    bbox = np.linalg.norm(v.max(0) - v.min(0))
    moved = targets + np.array([0.0, 0.002 * bbox, 0.0])
    t0 = time.perf_counter()
    rw = default.solve(moved, warm_start=True)
    dtw = time.perf_counter() - t0
    print(f"warm re-solve after a {0.002 * bbox:.4g} move (0.2% of bbox diagonal), from the "
          f"default-tolerance solve: {rw.iterations} iterations, {dtw * 1e3:.1f} ms, "
          f"converged={rw.converged}")
    # The same from a well converged previous solution (as after a few idle redraws with a
    # tight tolerance): the re-solve then only has to absorb the move, not the previous
    # solve's residual error.
    ref_m, _ = bind(tolerance=1e-10, max_iterations=1000)
    ref_m.solve(targets, warm_start=False)
    e_m = ref_m.solve(moved, warm_start=True).energy
    default.solve(targets, warm_start=True, tolerance=1e-10, max_iterations=1000)
    for tol in (1e-6, 1e-5, 1e-4):
        default.solve(targets, warm_start=True, tolerance=1e-10, max_iterations=1000)
        t0 = time.perf_counter()
        rw = default.solve(moved, warm_start=True, tolerance=tol)
        dtw = time.perf_counter() - t0
        print(f"warm re-solve after the same move from a converged solution, tolerance {tol:g}: "
              f"{rw.iterations} iterations, {dtw * 1e3:.1f} ms, energy "
              f"{(rw.energy / e_m - 1):.1e} above that target's minimum")

if __name__ == "__main__":
    main()

"""Compares what each Blender showed for the same scenes (tests/blender/test_cross_blender.py
wrote tests/blender/output/cross/<label>.npz in each), and checks that the newest Blender
reopened every older Blender's saved file without the add-on and showed the same meshes.

    /usr/bin/python3 tests/blender/compare_blenders.py LABEL [LABEL...]

Every label named must have recorded its scenes; each pair of Blenders must agree to 1e-6 of
each mesh's diagonal. Prints a table and "compare_blenders: N passed, N failed"."""
import json
import os
import sys

import numpy as np

CROSS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "output", "cross")
REL_TOL = 1e-6


def main(labels):
    passed = failed = 0

    def check(what, ok, detail=""):
        nonlocal passed, failed
        print("%s %s %s" % ("PASS" if ok else "FAIL", what, "" if ok else detail))
        passed += bool(ok)
        failed += not ok
        return ok

    recs = {}
    for lab in labels:
        path = os.path.join(CROSS, lab + ".npz")
        if check("%s recorded its scenes" % lab, os.path.isfile(path), path):
            recs[lab] = np.load(path)
    if len(recs) == len(labels) and labels:
        names = [str(n) for n in recs[labels[0]]["names"]]
        print("%-24s %s" % ("scene", "  ".join("%12s" % lab for lab in labels[1:])))
        for i, name in enumerate(names):
            diag = float(recs[labels[0]]["diag"][i])
            row = []
            for lab in labels[1:]:
                worst = 0.0
                for prefix in ("pos", "half"):   # frames 1 and 11: the keyed Factor 1 and 0.5
                    key = "%s:%s" % (prefix, name)
                    if key not in recs[lab].files or key not in recs[labels[0]].files:
                        check("%s and %s have %s" % (lab, labels[0], key), False)
                        worst = float("inf")
                        continue
                    rel = float(np.abs(recs[lab][key] - recs[labels[0]][key]).max() / diag)
                    worst = max(worst, rel)
                row.append("%12.1e" % worst)
                check("%s: %s = %s within %g of the diagonal on frames 1 and 11 (%.1e)"
                      % (name, lab, labels[0], REL_TOL, worst), worst <= REL_TOL, worst)
            print("%-24s %s" % (name, "  ".join(row)))
        newest = max(labels, key=lambda lab: tuple(int(x) for x in recs[lab]["version"]))
        with open(os.path.join(CROSS, newest + ".reloads.json")) as f:
            reloads = json.load(f)["reloaded"]
        for lab in labels:
            if lab == newest:
                continue
            if tuple(recs[lab]["version"]) < tuple(recs[newest]["version"]):
                check("%s reopened %s's file without the add-on, same meshes" % (newest, lab),
                      lab in reloads and reloads[lab] <= REL_TOL, reloads.get(lab))
    print("compare_blenders: %d passed, %d failed" % (passed, failed))
    return 1 if failed or not passed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env bash
# Sets everything up and runs every DeformKit test:
#   1. C tests (ctest, one per core at a time) in the Release build and in the ASan+UBSan build, then the libFuzzer
#      harnesses for a bounded 40 s in all (scripts/fuzz.sh --seconds 40: the mesh readers,
#      mesh construction, every method's bind and solve; clang, ASan+UBSan),
#   2. Python module tests (pytest under Debian's /usr/bin/python3; the property suite
#      tests/python/test_properties.py with its bounded, derandomized "ci" profile), and
#      again with the module of the ASan+UBSan build (the sanitizer runtimes preloaded;
#      leaving out the tests marked heavy: whole scanned meshes solved to convergence; this
#      one starts after the sanitized C tests and runs in the background beside everything
#      up to step 4, its output printed when it ends),
#   3. the packages: scripts/package.sh builds the wheel and the two add-on zips into dist/
#      (and validates the extension in every Blender 4.2+ here); the wheel is installed into
#      a clean virtual environment and smoke-tested there,
#   3b. farm bakes (tests/farm, in the [farm] environment): scripts/farm_bake.py on a Dask
#      scheduler and two workers started on loopback (chunks joined byte-identical to one
#      bake, a worker killed mid-chunk, a chunk failing for good) and the generated job files
#      for Open Job Description (openjd check / run), Flamenco (Node) and Slurm (a
#      single-node Slurm started by the test),
#   4. the add-on in every Blender (tests/blender/run_all.sh): Debian's `blender` program,
#      with the window suites under Xvfb, and each bpy-* environment of scripts/pins.txt
#      (the official releases as Python modules: 4.5 LTS, 5.2 LTS, 5.3), each also installing
#      its packaged zip into a clean user directory,
#   5. the cross-Blender comparison: the same scenes give the same meshes in every Blender,
#      and the newest reopens the others' saved files without the add-on.
# Ends with a matrix of Blender x suite, then one line "suites: N passed, N failed" that
# counts each Blender's suites, and exits non-zero if any suite failed.
#
# usage: scripts/test.sh [--quick]     (--quick skips the sanitized build and the fuzzers)
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
quick=0
[ "${1:-}" = "--quick" ] && quick=1
t_start=$SECONDS

if [ "$quick" = 1 ]; then
  scripts/setup.sh || { echo "suites: 0 passed, 1 failed"; exit 1; }
else
  scripts/setup.sh --asan --fuzz || { echo "suites: 0 passed, 1 failed"; exit 1; }
fi
# a Blender whose CPython the machine lacks is skipped by venvs.sh (which says what to
# install); its suites then fail below, and the rest still run
scripts/venvs.sh || echo "scripts/venvs.sh: some environments could not be made (see above)"

PY=/usr/bin/python3
export PYTHONPATH="$here/build/python"
export PYTHONDONTWRITEBYTECODE=1
passed=0; failed=0; failed_names=()
run_suite() {  # run_suite NAME COMMAND...
  local name="$1"; shift
  echo
  echo "=== $name: $*"
  local start=$SECONDS
  if "$@"; then
    passed=$((passed + 1)); echo "=== $name: ok ($((SECONDS - start)) s)"
  else
    failed=$((failed + 1)); failed_names+=("$name"); echo "=== $name: FAILED ($((SECONDS - start)) s)"
  fi
}

# A suite run beside the others (in the background, its output kept and printed when it is
# collected): the sanitized Python suite, about six minutes alone, overlaps the fuzzers,
# the Python tests, the packages, the farm and the Blender suites, which leave a core
# partly idle (single-threaded fuzzers and tests, Blender's start-up, subprocesses, waits).
bg_name=""; bg_pid=""; bg_log=""; bg_start=0
start_background_suite() {  # start_background_suite NAME COMMAND...
  bg_name="$1"; shift
  bg_log="$(mktemp)"; bg_start=$SECONDS
  echo
  echo "=== $bg_name: $* (started beside the suites below; its output follows when it ends)"
  # in a session of its own, so that an early end can stop it with all its subprocesses
  setsid bash -c 's=$SECONDS; "$@"; rc=$?; echo "(ended $((SECONDS - s)) s after its start)"
                 exit $rc' background "$@" >"$bg_log" 2>&1 &
  bg_pid=$!
}
finish_background_suite() {
  [ -n "$bg_pid" ] || return 0
  local rc=0
  wait "$bg_pid" || rc=$?
  echo
  echo "=== $bg_name (started earlier):"
  cat "$bg_log"; rm -f "$bg_log"
  if [ "$rc" = 0 ]; then
    passed=$((passed + 1)); echo "=== $bg_name: ok ($((SECONDS - bg_start)) s beside the others)"
  else
    failed=$((failed + 1)); failed_names+=("$bg_name")
    echo "=== $bg_name: FAILED ($((SECONDS - bg_start)) s beside the others)"
  fi
  bg_pid=""
}
matrix=""; log=""
on_exit() {  # an interrupted or failed run: the background suite stopped, what it printed kept
  rm -f "$matrix" "$log"
  if [ -n "$bg_pid" ]; then
    kill -- -"$bg_pid" 2>/dev/null
    wait "$bg_pid" 2>/dev/null
    echo "=== $bg_name: stopped before its end (the run ended); what it printed:"
    cat "$bg_log"; rm -f "$bg_log"
  fi
}
trap on_exit EXIT

# the C tests two at a time (each is its own process; the machines have two cores)
jobs="$(nproc 2>/dev/null || echo 2)"
run_suite "C tests" ctest --test-dir build --output-on-failure -j"$jobs"
if [ "$quick" = 0 ]; then
  run_suite "C tests (ASan+UBSan)" ctest --test-dir build-asan --output-on-failure -j"$jobs"
  # detect_leaks=0: the interpreter keeps memory at exit that LeakSanitizer would report (the
  # C tests run with leak detection on)
  start_background_suite "Python tests (ASan+UBSan)" env \
    LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)" \
    ASAN_OPTIONS=detect_leaks=0 PYTHONPATH="$here/build-asan/python" \
    "$PY" -m pytest -q -p no:cacheprovider -m "not heavy" tests/python
  run_suite "fuzzers (40 s)" scripts/fuzz.sh --no-setup --seconds 40
fi
run_suite "Python tests" "$PY" -m pytest -q tests/python
run_suite "package" scripts/package.sh --no-setup
run_suite "wheel in a clean venv" tests/wheel/test_wheel.sh
# farm bakes on a Dask scheduler and two workers started on loopback, and the job files for
# other farms (the [farm] environment of scripts/pins.txt: Dask, openjd-cli, Blender 5.2)
run_suite "farm" build/venvs/farm/bin/python -m pytest -q -p no:cacheprovider tests/farm

# ---- the add-on in each Blender: run_all.sh prints "ok NAME" / "FAILED NAME" per suite
blenders=(debian $(scripts/venvs.sh --blenders))
rm -rf tests/blender/output/cross
matrix="$(mktemp)"; log="$(mktemp)"
for b in "${blenders[@]}"; do
  echo
  echo "=== add-on in Blender ($b): tests/blender/run_all.sh --blender $b"
  start=$SECONDS
  tests/blender/run_all.sh --blender "$b" "$here/build" | tee "$log"
  rc=${PIPESTATUS[0]}
  sed -n "s/^\(ok\|FAILED\) *\([A-Za-z0-9_]*\).*/$b \1 \2/p" "$log" >>"$matrix"
  n_ok="$(grep -c "^$b ok " "$matrix")"; n_bad="$(grep -c "^$b FAILED " "$matrix")"
  passed=$((passed + n_ok)); failed=$((failed + n_bad))
  if [ "$rc" != 0 ] && [ "$n_bad" = 0 ]; then   # failed before any suite ran
    failed=$((failed + 1)); echo "$b FAILED setup" >>"$matrix"
  fi
  [ "$rc" = 0 ] || failed_names+=("add-on in Blender ($b)")
  echo "=== add-on in Blender ($b): $n_ok passed, $n_bad failed ($((SECONDS - start)) s)"
done
labels=()
for b in "${blenders[@]}"; do labels+=("$b"); done
finish_background_suite
run_suite "same results in every Blender" "$PY" tests/blender/compare_blenders.py "${labels[@]}"

echo
echo "Blender x suite (ok / FAILED / - not run there):"
"$PY" - "$matrix" "${blenders[@]}" <<'EOF'
import sys
rows, cols = {}, sys.argv[2:]
for line in open(sys.argv[1]):
    b, status, name = line.split()
    rows.setdefault(name, {})[b] = "ok" if status == "ok" else "FAILED"
width = max([len(n) for n in rows] + [10])
print("  %-*s %s" % (width, "suite", " ".join("%-8s" % c for c in cols)))
for name, cells in rows.items():
    print("  %-*s %s" % (width, name, " ".join("%-8s" % cells.get(c, "-") for c in cols)))
EOF
echo
if [ ${#failed_names[@]} -gt 0 ]; then echo "failed suites: ${failed_names[*]}"; fi
echo "wall time: $((SECONDS - t_start)) s"
echo "suites: $passed passed, $failed failed"
[ "$failed" -eq 0 ]

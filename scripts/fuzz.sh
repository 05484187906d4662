#!/usr/bin/env bash
# Builds the libFuzzer harnesses (tests/fuzz/, clang with ASan+UBSan, into build-fuzz/) and
# runs each one over its corpus tests/fuzz/corpus/<harness>/ (seeds, and the reproducers of
# every bug found, crash-*), for a share of the given time:
#   fuzz_mesh_obj, fuzz_mesh_off, fuzz_mesh_ply   the mesh readers        1 share each
#   fuzz_mesh_build                               mesh construction       1 share
#   fuzz_method                                   every method's bind,    3 shares
#                                                 solve, energy, rebind
# One process per harness (-jobs 1: the machine is shared). Every crash, leak, sanitizer
# report, harness invariant (tests/fuzz/fuzz_input.h) or input slower than --timeout is a
# failure: the input is saved under build-fuzz/artifacts/ and the script exits non-zero.
# What a run finds new is kept in build-fuzz/corpus/<harness>/, not in the repository, and
# is replayed first by the next run (on top of --seconds: fuzz_method runs ~8 inputs a
# second; delete build-fuzz/corpus/ to start from the seeds again, as CI does); a bug's
# reproducer goes into tests/fuzz/corpus/<harness>/crash-<what> with its fix.
#
# usage: scripts/fuzz.sh [--seconds N] [--timeout S] [--only HARNESS] [--no-setup]
#   --seconds N   total fuzzing time, shared out as above (default 60: CI's bounded run;
#                 by hand, e.g. --seconds 1200)
#   --timeout S   the slowest one input may be (default 25 s: under ASan on a loaded
#                 machine a refused EmbeddedDeformation radius takes up to 10 s)
#   --only H      run one harness (e.g. --only fuzz_method) for all the time
#   --no-setup    do not run scripts/setup.sh --fuzz --no-build first (clang installed)
# Ends with one line "fuzz: N passed, N failed" (harnesses).
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
seconds=60; timeout=25; only=""; setup=1
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --timeout) timeout="$2"; shift 2 ;;
    --only) only="$2"; shift 2 ;;
    --no-setup) setup=0; shift ;;
    *) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
if [ "$setup" = 1 ]; then
  scripts/setup.sh --fuzz --no-build || { echo "fuzz: 0 passed, 1 failed"; exit 1; }
fi

build="$here/build-fuzz"
cmake -S "$here" -B "$build" -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_BUILD_TYPE=Release \
  -DDK_FUZZ=ON -DDK_TESTS=OFF -DDK_PYTHON=OFF >/dev/null &&
  cmake --build "$build" -j2 >"$build/build.log" 2>&1 ||
  { cat "$build/build.log" >&2; echo "fuzz: 0 passed, 1 failed"; exit 1; }

harnesses=(fuzz_mesh_obj fuzz_mesh_off fuzz_mesh_ply fuzz_mesh_build fuzz_method)
shares=(1 1 1 1 3)
total_shares=7
if [ -n "$only" ]; then harnesses=("$only"); shares=(1); total_shares=1; fi

export OPENBLAS_NUM_THREADS=1
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:allocator_may_return_null=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
mkdir -p "$build/artifacts"
passed=0; failed=0
for i in "${!harnesses[@]}"; do
  h="${harnesses[$i]}"
  corpus="tests/fuzz/corpus/${h#fuzz_}"
  t=$(( seconds * shares[i] / total_shares )); [ "$t" -ge 1 ] || t=1
  work="$build/corpus/${h#fuzz_}"
  mkdir -p "$work"
  echo "=== $h: $t s over $corpus"
  log="$build/$h.log"
  # new inputs go to the scratch corpus (first directory); the repository's is read only
  "$build/$h" -max_total_time="$t" -timeout="$timeout" -rss_limit_mb=2048 -max_len=4096 \
    -print_final_stats=1 -artifact_prefix="$build/artifacts/$h-" "$work" "$corpus" \
    >"$log" 2>&1
  rc=$?
  stats="$(grep -E '^stat::(number_of_executed_units|new_units_added|peak_rss_mb)' "$log" |
           sed 's/^stat:://' | tr -s ' \n' ' ')"
  if [ "$rc" = 0 ]; then
    passed=$((passed + 1)); echo "ok $h ($stats)"
  else
    failed=$((failed + 1)); echo "FAILED $h (exit $rc; $stats)"
    grep -E 'ERROR|SUMMARY|runtime error|fuzz invariant|Test unit written' "$log" | head -20
  fi
done
echo "fuzz: $passed passed, $failed failed"
[ "$failed" -eq 0 ]

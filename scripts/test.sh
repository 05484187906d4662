#!/usr/bin/env bash
# Sets everything up and runs every DeformKit test:
#   1. C tests (ctest) in the Release build and in the ASan+UBSan build,
#   2. Python module tests (pytest under Debian's /usr/bin/python3),
#   3. the module and the add-on inside real Blender (blender -b --factory-startup),
#      and the UI screenshot test under Xvfb; then scripts/package.sh writes the zips to dist/
#      and the legacy zip is installed into a clean Blender user directory and tested
#      (tests/blender/run_all.sh).
# Ends with one line "suites: N passed, N failed" and exits non-zero if any suite failed.
#
# usage: scripts/test.sh [--quick]     (--quick skips the sanitized build)
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
quick=0
[ "${1:-}" = "--quick" ] && quick=1

if [ "$quick" = 1 ]; then
  scripts/setup.sh || { echo "suites: 0 passed, 1 failed"; exit 1; }
else
  scripts/setup.sh --asan || { echo "suites: 0 passed, 1 failed"; exit 1; }
fi

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

run_suite "C tests" ctest --test-dir build --output-on-failure
if [ "$quick" = 0 ]; then
  run_suite "C tests (ASan+UBSan)" ctest --test-dir build-asan --output-on-failure
fi
run_suite "Python tests" "$PY" -m pytest -q tests/python
blender_cmd=(blender -b --factory-startup --python-exit-code 1)
if [ -f tests/blender/test_module_blender.py ]; then
  run_suite "module in Blender" "${blender_cmd[@]}" --python tests/blender/test_module_blender.py
fi
if [ -x tests/blender/run_all.sh ]; then
  run_suite "add-on in Blender" tests/blender/run_all.sh "$here/build"
fi

echo
if [ "$failed" -gt 0 ]; then echo "failed suites: ${failed_names[*]}"; fi
echo "suites: $passed passed, $failed failed"
[ "$failed" -eq 0 ]

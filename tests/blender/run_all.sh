#!/usr/bin/env bash
# Runs every add-on test inside real Blender.
#   tests/blender/run_all.sh [BUILD_DIR]      (default: build; the module is in BUILD_DIR/python)
# Headless tests: blender -b --factory-startup --python-exit-code 1 --python FILE.
# Window tests (undo, screenshot): under xvfb-run. Ends with "add-on tests: N passed, N failed".
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
build="${1:-$root/build}"
case "$build" in /*) ;; *) build="$root/$build" ;; esac
if [ "${DEFORMKIT_MOCK:-0}" = 1 ]; then
  export PYTHONPATH="$here/mock"
else
  export PYTHONPATH="$build/python"
  if [ ! -d "$build/python/deformkit" ]; then
    echo "no native module in $build/python (build it first)"; echo "add-on tests: 0 passed, 1 failed"; exit 1
  fi
fi
export PYTHONDONTWRITEBYTECODE=1
mkdir -p "$here/output"
passed=0; failed=0; failed_names=()
run() {  # run NAME COMMAND...
  local name="$1"; shift
  local log="$here/output/$name.log"
  local start=$SECONDS
  if timeout 900 "$@" >"$log" 2>&1; then
    passed=$((passed + 1)); echo "ok     $name ($((SECONDS - start)) s): $(grep -E '[0-9]+ passed, [0-9]+ failed' "$log" | tail -1)"
  else
    failed=$((failed + 1)); failed_names+=("$name")
    echo "FAILED $name ($((SECONDS - start)) s), log $log:"; grep -E '^FAIL|Error|passed, ' "$log" | tail -20
  fi
}
for t in "$here"/test_addon_*.py; do
  name="$(basename "$t" .py)"
  if [ "$name" = test_addon_undo ] || [ "$name" = test_addon_modal ]; then
    run "$name" xvfb-run -a blender --factory-startup --enable-event-simulate --python "$t"
  else
    run "$name" blender -b --factory-startup --python-exit-code 1 --python "$t"
  fi
done
run pc2 /usr/bin/python3 -m pytest -q "$root/tests/python/test_pc2.py"
run screenshot_ui /usr/bin/python3 "$here/screenshot_ui.py"
[ "$failed" -gt 0 ] && echo "failed: ${failed_names[*]}"
echo "add-on tests: $passed passed, $failed failed"
[ "$failed" -eq 0 ]

#!/usr/bin/env bash
# Runs every add-on test inside real Blender.
#   tests/blender/run_all.sh [BUILD_DIR]      (default: build; the module is in BUILD_DIR/python)
# Headless tests: blender -b --factory-startup --python-exit-code 1 --python FILE.
# Window tests (undo, screenshot): under xvfb-run. Then the packaged add-on: scripts/package.sh
# builds dist/ from BUILD_DIR, and test_package plus test_addon_methods run against the legacy
# zip installed into a fresh Blender user directory, without PYTHONPATH (DEFORMKIT_FROM_ZIP).
# Ends with "add-on tests: N passed, N failed".
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
    local summary; summary="$(grep -E '[0-9]+ passed, [0-9]+ failed' "$log" | tail -1)"
    passed=$((passed + 1)); echo "ok     $name ($((SECONDS - start)) s): ${summary:-$(tail -1 "$log")}"
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

# ---- the packaged add-on (legacy zip: the one Blender 3.4 installs)
run_from_zip() {  # run_from_zip NAME SCRIPT: fresh user directory, no PYTHONPATH
  local user; user="$(mktemp -d "${TMPDIR:-/tmp}/deformkit-user.XXXXXX")"
  mkdir -p "$user/scripts" "$user/config"
  run "$1" env -u PYTHONPATH BLENDER_USER_SCRIPTS="$user/scripts" BLENDER_USER_CONFIG="$user/config" \
      DEFORMKIT_FROM_ZIP="$legacy_zip" blender -b --factory-startup --python-exit-code 1 --python "$2"
  rm -rf "$user"
}
if [ "${DEFORMKIT_MOCK:-0}" = 1 ]; then
  echo "skip   package tests (DEFORMKIT_MOCK=1: the stand-in module is not packaged)"
else
  version="$(/usr/bin/python3 -c 'import sys, tomllib
print(tomllib.load(open(sys.argv[1], "rb"))["version"])' "$root/blender_manifest.toml")"
  legacy_zip="$root/dist/deformkit-$version-legacy-linux_x64.zip"
  rm -f "$legacy_zip"
  run package "$root/scripts/package.sh" --build-dir "$build" --no-setup
  if [ -f "$legacy_zip" ]; then
    run_from_zip test_package "$here/test_package.py"
    run_from_zip test_addon_methods_from_zip "$here/test_addon_methods.py"
  else
    failed=$((failed + 2)); failed_names+=(test_package test_addon_methods_from_zip)
    echo "FAILED test_package, test_addon_methods_from_zip: no $legacy_zip"
  fi
fi
[ "$failed" -gt 0 ] && echo "failed: ${failed_names[*]}"
echo "add-on tests: $passed passed, $failed failed"
[ "$failed" -eq 0 ]

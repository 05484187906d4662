#!/usr/bin/env bash
# Runs the add-on's suites inside one Blender.
#   tests/blender/run_all.sh [--blender NAME] [BUILD_DIR]
# NAME: "debian" (default), the `blender` program on PATH (Debian's package), or a bpy-*
# environment of scripts/pins.txt (Blender as a Python module, made by scripts/venvs.sh).
# The module is taken from BUILD_DIR/python (default build). Needs the packages that
# scripts/package.sh wrote into dist/ (scripts/test.sh builds them first).
#
# In every Blender: the headless suites (the native module in Blender's Python, test_addon_*.py
# but undo and modal, the cross-Blender record), then the packaged add-on from a fresh user directory without PYTHONPATH: the
# extension zip in Blender 4.2+, the legacy zip before (test_package and test_addon_methods).
# In Debian's Blender also the window suites under Xvfb (undo, modal, the UI screenshot).
# Ends with "add-on tests (NAME): N passed, N failed".
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
blender_name=debian
if [ "${1:-}" = "--blender" ]; then blender_name="$2"; shift 2; fi
build="${1:-$root/build}"
case "$build" in /*) ;; *) build="$root/$build" ;; esac
if [ "${DEFORMKIT_MOCK:-0}" = 1 ]; then
  export PYTHONPATH="$here/mock"
else
  export PYTHONPATH="$build/python"
  if [ ! -d "$build/python/deformkit" ]; then
    echo "no native module in $build/python (build it first)"
    echo "add-on tests ($blender_name): 0 passed, 1 failed"; exit 1
  fi
fi
export PYTHONDONTWRITEBYTECODE=1 DEFORMKIT_BLENDER_LABEL="$blender_name"
# deprecation warnings shown (Python hides them outside __main__), so that no_warnings below
# sees any that this Blender raises for the add-on's code
export PYTHONWARNINGS="default::DeprecationWarning,default::FutureWarning"

if [ "$blender_name" = debian ]; then
  if ! command -v blender >/dev/null; then
    echo "no blender on PATH (scripts/setup.sh installs Debian's)"
    echo "add-on tests (debian): 0 passed, 1 failed"; exit 1
  fi
  headless=(blender -b --factory-startup --python-exit-code 1 --python)
  version="$(blender --version 2>/dev/null | sed -n 's/^Blender \([0-9.]*\).*/\1/p' | head -1)"
else
  py="$root/build/venvs/$blender_name/bin/python"
  if [ ! -x "$py" ]; then
    echo "no $py (scripts/venvs.sh $blender_name makes it)"
    echo "add-on tests ($blender_name): 0 passed, 1 failed"; exit 1
  fi
  headless=("$py")
  version="$("$py" -c 'import bpy, os, sys
sys.stdout.write("%d.%d.%d" % bpy.app.version); sys.stdout.flush(); os._exit(0)' 2>/dev/null)"
fi
if [ -z "$version" ]; then
  echo "could not start Blender ($blender_name)"
  echo "add-on tests ($blender_name): 0 passed, 1 failed"; exit 1
fi
echo "Blender $version ($blender_name)"
out="$here/output/$blender_name"
mkdir -p "$out"
passed=0; failed=0; failed_names=()
run() {  # run NAME COMMAND...   (in a fresh user directory, so no preference leaks in)
  local name="$1"; shift
  local log="$out/$name.log" start=$SECONDS user
  user="$(mktemp -d "${TMPDIR:-/tmp}/deformkit-user.XXXXXX")"
  mkdir -p "$user/scripts" "$user/config"
  if BLENDER_USER_RESOURCES="$user" BLENDER_USER_SCRIPTS="$user/scripts" \
     BLENDER_USER_CONFIG="$user/config" timeout 900 "$@" >"$log" 2>&1; then
    local summary; summary="$(grep -E '[0-9]+ passed, [0-9]+ failed' "$log" | tail -1)"
    passed=$((passed + 1)); echo "ok     $name ($((SECONDS - start)) s): ${summary:-$(tail -1 "$log")}"
  else
    failed=$((failed + 1)); failed_names+=("$name")
    echo "FAILED $name ($((SECONDS - start)) s), log $log:"; grep -E '^FAIL|Error|passed, ' "$log" | tail -20
  fi
  rm -rf "$user"
}
for t in "$here/test_module_blender.py" "$here"/test_addon_*.py "$here/test_cross_blender.py"; do
  name="$(basename "$t" .py)"
  case "$name" in
    test_addon_undo|test_addon_modal)
      if [ "$blender_name" = debian ]; then
        run "$name" xvfb-run -a blender --factory-startup --enable-event-simulate --python "$t"
      fi ;;
    *) run "$name" "${headless[@]}" "$t" ;;
  esac
done
if [ "$blender_name" = debian ]; then
  run screenshot_ui /usr/bin/python3 "$here/screenshot_ui.py"
fi

# ---- the packaged add-on: the extension zip in 4.2+, the legacy zip before
if [ "${DEFORMKIT_MOCK:-0}" = 1 ]; then
  echo "skip   package tests (DEFORMKIT_MOCK=1: the stand-in module is not packaged)"
else
  pkg_version="$(/usr/bin/python3 -c 'import sys, tomllib
m = tomllib.load(open(sys.argv[1], "rb")); print(m["id"], m["version"])' "$root/blender_manifest.toml")"
  read -r pkg_id pkg_version <<<"$pkg_version"
  if [ "$(printf '%s\n4.2.0\n' "$version" | sort -V | head -1)" = 4.2.0 ]; then
    zip="$root/dist/$pkg_id-$pkg_version-linux_x64.zip"; kind=extension
  else
    zip="$root/dist/$pkg_id-$pkg_version-legacy-linux_x64.zip"; kind=legacy
  fi
  if [ -f "$zip" ]; then
    for t in test_package test_addon_methods; do
      run "${t}_from_$kind" env -u PYTHONPATH DEFORMKIT_FROM_ZIP="$zip" "${headless[@]}" "$here/$t.py"
    done
  else
    for t in test_package test_addon_methods; do
      failed=$((failed + 1)); failed_names+=("${t}_from_$kind")
      echo "FAILED ${t}_from_$kind: no $zip (run scripts/package.sh)"
    done
  fi
fi
# ---- no Python warning raised in the add-on's code, in any suite above
run no_warnings bash -c '! grep -HnE "Warning: .*|^(.*/)?(addon|deformkit_addon)/[a-z_]+\.py:[0-9]+: [A-Za-z]*Warning" "$0"/*.log | grep -E "(addon|deformkit_addon)/[a-z_]+\.py"' "$out"
[ "$failed" -gt 0 ] && echo "failed: ${failed_names[*]}"
echo "add-on tests ($blender_name): $passed passed, $failed failed"
[ "$failed" -eq 0 ]

#!/usr/bin/env bash
# The DeformKit demo. Sets everything up (scripts/setup.sh: Debian packages if missing, CMake
# build into build/; scripts/venvs.sh: the pinned Blenders as Python modules), then runs
# scripts/demo_blender.py in the newest Blender the machine has (headless: the newest bpy
# environment, or Debian's blender program if that is newer) with the native module from
# build/python and the add-on from addon/: each method of the add-on deforms the shared
# arm-lift and armadillo-wave scenarios, is measured, rendered (Cycles, CPU) and saved.
#
# usage: scripts/demo.sh [demo options]        (scripts/demo.sh --help lists them)
# Writes into demo_output/: <scenario>_rest.png, <scenario>_<method>.png, <scenario>_all.png,
# deformkit_demo.blend, summary.txt, summary.json, and blender.log (Blender's own output).
# The shared data (meshes/, scenarios/) is $DEFORMKIT_SHARED, else ../shared beside the
# repository. Exits non-zero on any failure.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
for arg in "$@"; do
  if [ "$arg" = -h ] || [ "$arg" = --help ]; then
    PYTHONPATH="$here/build/python" blender -b --factory-startup --python-exit-code 1 \
      --python scripts/demo_blender.py -- --help 2>&1 | sed -n '/^usage:/,$p' | grep -v '^Blender quit'
    exit 0
  fi
done
start=$SECONDS
scripts/setup.sh
# a Blender whose CPython this machine lacks is skipped (venvs.sh says what to install)
scripts/venvs.sh $(scripts/venvs.sh --blenders) || echo "demo: some Blenders could not be set up" >&2
mkdir -p demo_output
export PYTHONPATH="$here/build/python"
export PYTHONDONTWRITEBYTECODE=1

# the most recent Blender here: each bpy environment's pinned version, and Debian's program
newest=debian
newest_version="$(blender --version 2>/dev/null | sed -n 's/^Blender \([0-9.]*\).*/\1/p' | head -1)"
for b in $(scripts/venvs.sh --blenders); do
  v="$(sed -n "/^\[$b\]/,/^\[/s/^bpy==\([0-9.]*\).*/\1/p" scripts/pins.txt)"
  [ -x "build/venvs/$b/bin/python" ] || continue
  if [ -n "$v" ] && [ "$(printf '%s\n%s\n' "${newest_version:-0}" "$v" | sort -V | tail -1)" = "$v" ]; then
    newest="$b"; newest_version="$v"
  fi
done
echo "demo: running Blender $newest_version ($newest; its own output: demo_output/blender.log)" >&2
status=0
if [ "$newest" = debian ]; then
  blender -b --factory-startup --python-exit-code 1 --python scripts/demo_blender.py -- "$@" \
    >demo_output/blender.log || status=$?
else
  "build/venvs/$newest/bin/python" scripts/demo_blender.py -- "$@" >demo_output/blender.log \
    || status=$?
fi
if [ "$status" != 0 ]; then
  echo "demo: FAILED (exit $status); Blender's output: demo_output/blender.log" >&2
  exit "$status"
fi
echo "demo: done in $((SECONDS - start)) s (setup included)" >&2

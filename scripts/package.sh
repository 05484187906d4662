#!/usr/bin/env bash
# Builds the installable DeformKit zips into dist/ (git-ignored):
#   dist/deformkit-<version>-linux_x64.zip          Blender 4.2+ extension (install from disk)
#   dist/deformkit-<version>-legacy-linux_x64.zip   Blender 3.4-4.1 (Preferences > Add-ons > Install)
# Version, name and tagline come from blender_manifest.toml; packaging fails if bl_info or the
# native package's version disagree. The native module is built first (Release) and bundled
# with its shared libraries; see scripts/package.py and docs/addon.md, "Packaging".
#
# usage: scripts/package.sh [--build-dir DIR] [--out DIR] [--no-setup]
#   --build-dir DIR  CMake build to package (default build/; configured Release if new)
#   --out DIR        where the zips go (default dist/)
#   --no-setup       do not run scripts/setup.sh (no package installs; tests use this)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$root/build"; out="$root/dist"; setup=1
while [ $# -gt 0 ]; do
  case "$1" in
    --build-dir) build="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --no-setup) setup=0; shift ;;
    *) echo "package.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
case "$build" in /*) ;; *) build="$PWD/$build" ;; esac
case "$out" in /*) ;; *) out="$PWD/$out" ;; esac

if [ "$setup" = 1 ]; then
  "$root/scripts/setup.sh" --no-build
fi
for tool in patchelf readelf ldd cmake; do
  command -v "$tool" >/dev/null || { echo "package.sh: $tool not found (run scripts/setup.sh)" >&2; exit 1; }
done
quiet() {  # run quietly; show the output if it fails
  local out; if ! out="$("$@" 2>&1)"; then echo "$out" >&2; echo "package.sh: failed: $*" >&2; exit 1; fi
}
if [ ! -f "$build/CMakeCache.txt" ]; then
  quiet cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release
fi
if grep -q '^DK_SANITIZE:BOOL=ON' "$build/CMakeCache.txt"; then
  echo "package.sh: $build is a sanitizer build (no Python module); package a Release build" >&2
  exit 1
fi
quiet cmake --build "$build" --target deformkit_native -j"$(nproc 2>/dev/null || echo 2)"
exec /usr/bin/python3 "$root/scripts/package.py" --build-dir "$build" --out "$out"

#!/usr/bin/env bash
# Builds the installable DeformKit files into dist/ (git-ignored):
#   dist/deformkit-<version>-cp311-abi3-manylinux_*_x86_64.whl   the native module (pip install)
#   dist/deformkit_addon-<version>-linux_x64.zip         Blender 4.2+ extension (install from disk)
#   dist/deformkit_addon-<version>-legacy-linux_x64.zip  Blender 3.4-4.1 (Preferences > Add-ons)
# Version, name and tagline come from blender_manifest.toml; packaging fails if bl_info,
# pyproject.toml or the native package's version disagree. The wheel is built by
# scikit-build-core and repaired by auditwheel in build/venvs/tools (scripts/venvs.sh, pinned
# in scripts/pins.txt); see scripts/package.py and docs/addon.md, "Packaging".
#
# usage: scripts/package.sh [--out DIR] [--no-setup]
#   --out DIR        where the files go (default dist/)
#   --no-setup       do not run scripts/setup.sh or scripts/venvs.sh (tests use this)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/dist"; setup=1
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="$2"; shift 2 ;;
    --no-setup) setup=0; shift ;;
    *) echo "package.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
case "$out" in /*) ;; *) out="$PWD/$out" ;; esac

if [ "$setup" = 1 ]; then
  "$root/scripts/setup.sh" --no-build
  "$root/scripts/venvs.sh" tools
fi
for tool in readelf ldd cmake dpkg; do
  command -v "$tool" >/dev/null || { echo "package.sh: $tool not found (run scripts/setup.sh)" >&2; exit 1; }
done
exec /usr/bin/python3 "$root/scripts/package.py" --out "$out"

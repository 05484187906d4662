#!/usr/bin/env bash
# Makes the virtual environments of scripts/pins.txt under build/venvs/<section>, with the
# CPython 3.11 that is first on PATH (the bpy wheels exist for CPython 3.11 only). An
# environment whose pins and interpreter are unchanged is left as it is: a rerun installs
# nothing. Prints each environment's path as it is made or found.
#
# usage: scripts/venvs.sh [SECTION...]     (default: every section)
#        scripts/venvs.sh --list           the section names, one a line
#        scripts/venvs.sh --blenders       the bpy-* section names, one a line
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
pins="$root/scripts/pins.txt"
sections() { sed -n 's/^\[\([A-Za-z0-9_.-]*\)\].*/\1/p' "$pins"; }
requirements() {  # the pinned lines of one section
  awk -v want="[$1]" '/^\[/ { on = ($1 == want); next } on && NF && $1 !~ /^#/ { print $1 }' "$pins"
}
case "${1:-}" in
  --list) sections; exit 0 ;;
  --blenders) sections | grep '^bpy-' || true; exit 0 ;;
esac

py="$(command -v python3.11 || true)"
if [ -z "$py" ]; then
  echo "venvs: no python3.11 on PATH (the bpy wheels and the tools are installed with it)" >&2
  exit 1
fi
if [ $# -eq 0 ]; then set -- $(sections); fi
for name in "$@"; do
  reqs="$(requirements "$name")"
  if [ -z "$reqs" ]; then echo "venvs: no section [$name] in $pins" >&2; exit 1; fi
  dir="$root/build/venvs/$name"
  want="$("$py" -c 'import sys; print(sys.executable, sys.version.split()[0])') $(echo $reqs)"
  if [ -f "$dir/.pins" ] && [ "$(cat "$dir/.pins")" = "$want" ] && [ -x "$dir/bin/python" ]; then
    echo "venvs: $dir (up to date)" >&2
    continue
  fi
  echo "venvs: making $dir: $(echo $reqs)" >&2
  rm -rf "$dir"
  "$py" -m venv "$dir"
  # --no-deps: the pins list every dependency; pip check below proves the set complete
  "$dir/bin/python" -m pip install --disable-pip-version-check --no-input -q --no-deps $reqs
  "$dir/bin/python" -m pip check --disable-pip-version-check >&2
  echo "$want" > "$dir/.pins"
done

#!/usr/bin/env bash
# Makes the virtual environments of scripts/pins.txt under build/venvs/<section>, each with the
# CPython its `python = X.Y` line names. The interpreter is found on this machine, never
# downloaded: scripts/find_python.sh X.Y tries the candidates by running them (a `python3.13`
# on PATH may be a pyenv shim that answers "command not found"). An environment whose pins and
# interpreter are unchanged is left as it is: a rerun installs nothing. A section whose CPython
# the machine lacks is skipped with a message naming what to install; the others are still
# made, and the exit status is 1.
#
# usage: scripts/venvs.sh [SECTION...]     (default: every section)
#        scripts/venvs.sh --list           the section names, one a line
#        scripts/venvs.sh --blenders       the bpy-* section names, one a line
#        scripts/venvs.sh --python SECTION the CPython version (X.Y) a section wants
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
pins="$root/scripts/pins.txt"
sections() { sed -n 's/^\[\([A-Za-z0-9_.-]*\)\].*/\1/p' "$pins"; }
section_lines() {  # the non-comment lines of one section
  awk -v want="[$1]" '/^\[/ { on = ($1 == want); next } on && NF && $1 !~ /^#/' "$pins"
}
requirements() { section_lines "$1" | awk '$1 != "python" { print $1 }'; }
python_version() { section_lines "$1" | awk '$1 == "python" && $2 == "=" { print $3 }'; }
case "${1:-}" in
  --list) sections; exit 0 ;;
  --blenders) sections | grep '^bpy-' || true; exit 0 ;;
  --python) python_version "$2"; exit 0 ;;
esac

if [ $# -eq 0 ]; then set -- $(sections); fi
status=0
for name in "$@"; do
  reqs="$(requirements "$name")"
  if [ -z "$reqs" ]; then echo "venvs: no section [$name] in $pins" >&2; exit 1; fi
  want_py="$(python_version "$name")"
  if [ -z "$want_py" ]; then echo "venvs: section [$name] names no 'python = X.Y'" >&2; exit 1; fi
  if ! py="$("$root/scripts/find_python.sh" "$want_py")"; then
    echo "venvs: skipping [$name]: it needs CPython $want_py (see above)" >&2
    status=1
    continue
  fi
  dir="$root/build/venvs/$name"
  want="$("$py" -c 'import sys; print(sys.executable, sys.version.split()[0])') $(echo $reqs)"
  if [ -f "$dir/.pins" ] && [ "$(cat "$dir/.pins")" = "$want" ] && [ -x "$dir/bin/python" ]; then
    echo "venvs: $dir (up to date)" >&2
    continue
  fi
  echo "venvs: making $dir with $py: $(echo $reqs)" >&2
  rm -rf "$dir"
  "$py" -m venv "$dir"
  # --no-deps: the pins list every dependency; pip check below proves the set complete
  "$dir/bin/python" -m pip install --disable-pip-version-check --no-input -q --no-deps $reqs
  "$dir/bin/python" -m pip check --disable-pip-version-check >&2
  echo "$want" > "$dir/.pins"
done
exit $status

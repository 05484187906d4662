#!/usr/bin/env bash
# Prints the path of a working CPython X.Y on this machine, or says on stderr what to install
# and exits 1. Nothing is downloaded. Each candidate is run, not trusted by its name: on these
# machines `python3.13` on PATH can be a pyenv shim that answers "command not found" when
# pyenv's global version is another one. A candidate counts when it reports version X.Y and
# can make a virtual environment with pip (venv and ensurepip import).
#
# Candidates, in order: pythonX.Y on PATH; /usr/bin/pythonX.Y (Debian's: 3.11 on Debian 12,
# 3.13 on Debian 13); /usr/local/bin/pythonX.Y; the CPythons under pyenv's versions folder
# ($PYENV_ROOT, else ~/.pyenv), newest patch release first.
#
# usage: scripts/find_python.sh X.Y
set -uo pipefail
want="${1:?usage: find_python.sh X.Y}"
case "$want" in [0-9].[0-9]|[0-9].[0-9][0-9]) ;; *) echo "find_python: not X.Y: $want" >&2; exit 2 ;; esac

candidates=()
onpath="$(command -v "python$want" 2>/dev/null || true)"
[ -n "$onpath" ] && candidates+=("$onpath")
candidates+=("/usr/bin/python$want" "/usr/local/bin/python$want")
pyenv_root="${PYENV_ROOT:-$HOME/.pyenv}"
if [ -d "$pyenv_root/versions" ]; then
  while IFS= read -r v; do
    candidates+=("$pyenv_root/versions/$v/bin/python$want")
  done < <(ls "$pyenv_root/versions" 2>/dev/null | grep -E "^$want\.[0-9]+$" | sort -rV)
fi

tried=()
for c in "${candidates[@]}"; do
  [ -x "$c" ] || continue
  got="$("$c" -c 'import sys, venv, ensurepip; print("%d.%d" % sys.version_info[:2])' 2>/dev/null)"
  if [ "$got" = "$want" ]; then
    echo "$c"
    exit 0
  fi
  tried+=("$c")
done
{
  echo "find_python: no working CPython $want on this machine."
  [ ${#tried[@]} -gt 0 ] && echo "  tried and failed to run (or without venv/ensurepip): ${tried[*]}"
  echo "  Install one of: Debian's python$want with python$want-venv (Debian 13 has 3.13,"
  echo "  Debian 12 has 3.11), or a CPython $want under pyenv (pyenv install $want)."
} >&2
exit 1

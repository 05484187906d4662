#!/usr/bin/env bash
# The wheel as a pipeline user gets it: `pip install` of dist/deformkit-*.whl into a clean
# virtual environment (the CPython 3.11 first on PATH, nothing else installed, nothing
# downloaded), then tests/wheel/smoke.py in that environment's Python, from outside the
# repository, checking that the module and its bundled libraries come from site-packages.
# Ends with "wheel: N passed, N failed".
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
fail() { echo "FAIL $*"; echo "wheel: 0 passed, 1 failed"; exit 1; }
shopt -s nullglob
wheels=("$root"/dist/deformkit-*-cp311-abi3-manylinux_*_x86_64.whl)
[ ${#wheels[@]} -eq 1 ] || fail "expected one wheel in dist/ (scripts/package.sh), found ${#wheels[@]}"
py="$(command -v python3.11 || true)"
[ -n "$py" ] || fail "no python3.11 on PATH"
venv="$(mktemp -d "${TMPDIR:-/tmp}/deformkit-wheel.XXXXXX")"
trap 'rm -rf "$venv"' EXIT
"$py" -m venv "$venv" || fail "venv"
env -u PYTHONPATH "$venv/bin/python" -m pip install --disable-pip-version-check --no-index \
    --no-deps -q "${wheels[0]}" || fail "pip install ${wheels[0]}"
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("platlib"))')"
cd "$venv" || fail "cd"
if env -u PYTHONPATH "$venv/bin/python" -I "$root/tests/wheel/smoke.py" --under "$site"; then
  echo "wheel: 1 passed, 0 failed"
else
  echo "wheel: 0 passed, 1 failed"; exit 1
fi

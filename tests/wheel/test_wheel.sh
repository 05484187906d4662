#!/usr/bin/env bash
# The wheel as a pipeline user gets it: `pip install` of dist/deformkit-*.whl into a clean
# virtual environment (nothing else installed, nothing downloaded), then tests/wheel/smoke.py
# in that environment's Python, from outside the repository, checking that the module and its
# bundled libraries come from site-packages. Once in each CPython the wheel is for: 3.11, the
# version its Limited API tag names (cp311-abi3), and 3.13, which the same binary must load
# unchanged (the Python of Blender 5.1 and later). Each interpreter is found by
# scripts/find_python.sh; a missing one fails its check and says what to install.
# Ends with "wheel: N passed, N failed".
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
fail() { echo "FAIL $*"; echo "wheel: 0 passed, 1 failed"; exit 1; }
shopt -s nullglob
wheels=("$root"/dist/deformkit-*-cp311-abi3-manylinux_*_x86_64.whl)
[ ${#wheels[@]} -eq 1 ] || fail "expected one wheel in dist/ (scripts/package.sh), found ${#wheels[@]}"
passed=0; failed=0
for version in 3.11 3.13; do
  echo "--- CPython $version"
  if ! py="$("$root/scripts/find_python.sh" "$version")"; then
    echo "FAIL no CPython $version"; failed=$((failed + 1)); continue
  fi
  venv="$(mktemp -d "${TMPDIR:-/tmp}/deformkit-wheel.XXXXXX")"
  if "$py" -m venv "$venv" \
     && env -u PYTHONPATH "$venv/bin/python" -m pip install --disable-pip-version-check \
          --no-index --no-deps -q "${wheels[0]}" \
     && site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("platlib"))')" \
     && (cd "$venv" && env -u PYTHONPATH "$venv/bin/python" -I "$root/tests/wheel/smoke.py" \
           --under "$site"); then
    echo "PASS the wheel in CPython $version ($py)"; passed=$((passed + 1))
  else
    echo "FAIL the wheel in CPython $version ($py)"; failed=$((failed + 1))
  fi
  rm -rf "$venv"
done
echo "wheel: $passed passed, $failed failed"
[ "$failed" -eq 0 ]

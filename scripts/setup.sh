#!/usr/bin/env bash
# Sets up a Debian machine for DeformKit and builds it. Safe to run again and again: installs
# only the Debian packages that are missing (apt-get update first, then apt-get install -y),
# then configures and builds with CMake into build/ (Release) and, with --asan, into
# build-asan/ (AddressSanitizer + UndefinedBehaviorSanitizer: the C library, the C tests and the
# Python module, which scripts/test.sh runs with the sanitizer runtimes preloaded).
#
# TetGen (the volume of bounded biharmonic weights, native/operators/tetrahedralize.cpp) is
# Debian's libtet<version>-dev: libtet1.5-dev in Debian 12, libtet1.6-dev in 13; the newest
# apt-cache knows is taken (after apt-get update when none is installed). g++ builds the one
# C++ file that calls TetGen's C++ API.
#
# python3-venv lets Debian's own CPython make virtual environments (scripts/venvs.sh finds
# Debian 13's /usr/bin/python3.13 for the Blenders from 5.1; tests/wheel/test_wheel.sh).
# nodejs runs the Flamenco job type's compileJob in tests/farm (the farm bakes' job files);
# slurmctld, slurmd, slurm-client and munge let tests/farm run the Slurm scripts on a
# single-node Slurm of its own (tests/farm/slurm_node.py: its own key, socket, ports and
# folder; the system's services are neither configured nor started by the tests).
# patchelf is for scripts/package.sh (it bundles the native libraries into the add-on zips).
# python3-hypothesis is for the property suite (tests/python/test_properties.py), which runs
# under Debian's python3 like the other Python tests (hypothesis is also pinned in
# scripts/pins.txt's [tools] venv; Debian 12 ships 6.67, Debian 13 6.130: the suite uses
# only long-standing API). Checked on packages.debian.org (2026-12-02): trixie has
# libarpack2-dev 3.9.1, python3-hypothesis 6.130.5 and blender 4.3.2 (the add-on's headless
# suites then run in Debian's 4.3 instead of 3.4); libclang-rt-dev is optional (installed
# only where apt-cache knows it).
#
# usage: scripts/setup.sh [--asan] [--bench] [--fuzz] [--no-build]
#   --asan      also build the sanitized configuration
#   --bench     also install what the benchmarks need (g++, CGAL, Eigen, scipy)
#   --fuzz      also install what the fuzzers need (Debian's unversioned clang, and
#               libclang-rt-dev where the distribution has it: its compiler-rt holds
#               libFuzzer and the sanitizers' runtimes, only a Recommends of clang);
#               scripts/fuzz.sh builds build-fuzz/
#   --no-build  only install packages
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
asan=0; bench=0; fuzz=0; build=1
for arg in "$@"; do
  case "$arg" in
    --asan) asan=1 ;;
    --bench) bench=1 ;;
    --fuzz) fuzz=1 ;;
    --no-build) build=0 ;;
    *) echo "setup.sh: unknown option $arg" >&2; exit 2 ;;
  esac
done

packages=(cmake make gcc g++ pkg-config libsuitesparse-dev libarpack2-dev liblapacke-dev
          libopenblas-dev python3-dev python3-numpy python3-scipy python3-pytest blender xvfb
          xauth zip patchelf python3-hypothesis python3-venv nodejs slurmctld slurmd
          slurm-client munge)
if [ "$bench" = 1 ]; then packages+=(libcgal-dev libeigen3-dev); fi
# installed when the distribution has them (libclang-rt-dev is in Debian 12's llvm-defaults;
# without it clang's Recommends bring the versioned runtime)
optional=()
if [ "$fuzz" = 1 ]; then packages+=(clang); optional+=(libclang-rt-dev); fi

installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
# the newest libtet<version>-dev apt-cache knows (empty when it knows none yet)
tetgen_dev() { apt-cache pkgnames libtet 2>/dev/null | grep -E '^libtet[0-9.]+-dev$' | sort -V | tail -n 1; }
tetgen_installed() {
  dpkg-query -W -f='${Package} ${Status}\n' 'libtet*-dev' 2>/dev/null | grep -q "install ok installed"
}
missing=(); missing_optional=(); need_tetgen=0
for p in "${packages[@]}"; do installed "$p" || missing+=("$p"); done
for p in "${optional[@]}"; do installed "$p" || missing_optional+=("$p"); done
tetgen_installed || need_tetgen=1
if [ ${#missing[@]} -gt 0 ] || [ ${#missing_optional[@]} -gt 0 ] || [ "$need_tetgen" = 1 ]; then
  sudo_cmd=()
  if [ "$(id -u)" != 0 ]; then sudo_cmd=(sudo); fi
  "${sudo_cmd[@]}" apt-get update
  if [ "$need_tetgen" = 1 ]; then
    t="$(tetgen_dev)"
    if [ -z "$t" ]; then echo "setup: apt-cache knows no libtet*-dev (TetGen)" >&2; exit 1; fi
    missing+=("$t")
  fi
  for p in "${missing_optional[@]}"; do
    if apt-cache show "$p" >/dev/null 2>&1; then missing+=("$p"); fi
  done
  echo "setup: installing ${missing[*]}" >&2
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y "${missing[@]}"
else
  echo "setup: all Debian packages present" >&2
fi

[ "$build" = 1 ] || exit 0
jobs="$(nproc 2>/dev/null || echo 2)"
cmake -S "$here" -B "$here/build" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$here/build" -j"$jobs"
if [ "$asan" = 1 ]; then
  cmake -S "$here" -B "$here/build-asan" -DCMAKE_BUILD_TYPE=Debug -DDK_SANITIZE=ON >/dev/null
  cmake --build "$here/build-asan" -j"$jobs"
fi
if [ "$asan" = 1 ]; then echo "setup: built build/ and build-asan/" >&2; else echo "setup: built build/" >&2; fi

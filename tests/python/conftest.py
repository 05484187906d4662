"""Shared set-up for the deformkit module tests.

The tests import the *built* module: run them as

    PYTHONPATH=build/python /usr/bin/python3 -m pytest tests/python

(any build directory works: build-py/python, build-asan/python, ...). Nothing here adds
paths or builds anything; when deformkit cannot be imported the session stops with a message
saying what to do.

The fixtures below generate small meshes with numpy so the tests run anywhere; tests that
read the real meshes under ../shared/meshes skip when those are absent.
"""

import os
import importlib.util
import pathlib

import numpy as np
import pytest

try:
    import deformkit  # noqa: F401
except ImportError as exc:  # pragma: no cover - only when misconfigured
    pytest.exit(
        "cannot import deformkit ({}): build the module first "
        "(cmake -S . -B build && cmake --build build) and run the tests with "
        "PYTHONPATH=build/python /usr/bin/python3 -m pytest tests/python".format(exc),
        returncode=1,
    )

def _under_address_sanitizer():
    """True when AddressSanitizer's runtime is loaded (the module built with DK_SANITIZE and
    run with it preloaded, as scripts/test.sh does)."""
    try:
        with open("/proc/self/maps") as f:
            return "libasan" in f.read()
    except OSError:
        return False


# ASan keeps freed memory in quarantine and maps shadow memory, so a process's resident size
# grows however well the module frees and exceeds any estimate of a bind's: tests that
# measure it skip there (leaks are LeakSanitizer's job in the C tests, which run with leak
# detection on)
UNDER_ASAN = _under_address_sanitizer()
measures_rss = pytest.mark.skipif(
    UNDER_ASAN, reason="AddressSanitizer's shadow memory and quarantine grow the resident size")



def pytest_configure(config):
    config.addinivalue_line(
        "markers", "heavy: a whole real scanned mesh solved to convergence; the sanitized run "
        "(scripts/test.sh, 5-10x slower) leaves these out with -m 'not heavy', since smaller "
        "tests take the same code paths")


def _controls(name):
    return deformkit._native._method_info(name)["controls"]


# The methods driven by vertex groups of the mesh (handles, fixed, region): the tests that
# bind with handles run over these. The methods bound to a control instead (dk_controls.h:
# a lattice) have their own contract tests (test_contract.py) and files.
GROUP_METHODS = tuple(m for m in deformkit.METHODS if "vertex_groups" in _controls(m))
CONTROL_METHODS = tuple(m for m in deformkit.METHODS if m not in GROUP_METHODS)

_spec = importlib.util.spec_from_file_location(
    "dk_enclosing_cage", pathlib.Path(__file__).resolve().parents[2] / "addon" / "enclosing_cage.py")
_enclosing_cage = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_enclosing_cage)

SHARED_MESHES = pathlib.Path(
    os.environ.get("DK_SHARED_DIR", pathlib.Path(__file__).resolve().parents[2] / ".." / "shared")
) / "meshes"


def make_icosphere(subdivisions=2, radius=1.0):
    """Icosahedron subdivided `subdivisions` times (midpoints projected to the sphere): the
    add-on's own (addon/enclosing_cage.py, Make Cage's sphere; pure numpy)."""
    V, F = _enclosing_cage.icosphere(subdivisions)
    return V * radius, F


def make_grid(nx=8, ny=6, bump=0.0, jitter=0.0, seed=0):
    """A (nx+1) x (ny+1) vertex grid on [0,1]^2 split into triangles, optionally bumped in z
    and jittered in x/y (jitter breaks the symmetries that make eigenvalues repeat)."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), indexing="ij")
    x, y = xs.ravel(), ys.ravel()
    if jitter:
        inner = (x > 0) & (x < 1) & (y > 0) & (y < 1)
        x = x + inner * rng.uniform(-jitter, jitter, x.shape) / nx
        y = y + inner * rng.uniform(-jitter, jitter, y.shape) / ny
    z = bump * np.sin(np.pi * x) * np.sin(np.pi * y)
    verts = np.stack([x, y, z], axis=1)
    idx = lambda i, j: i * (ny + 1) + j  # noqa: E731
    faces = []
    for i in range(nx):
        for j in range(ny):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            faces += [(a, b, c), (a, c, d)]
    return verts, np.array(faces, dtype=np.int64)


def make_book(pages=3, n=6, spine=8):
    """`pages` flat grids of n x spine vertices glued along a common spine (the line x = 0):
    every spine edge has one triangle per page, so all are non-manifold for pages > 2.
    Page k leaves the spine at angle 2 pi k / pages. Returns (v, f, page index per vertex)."""
    zs = np.linspace(0.0, 1.0, spine)
    v = [[0.0, 0.0, z] for z in zs]
    page = [-1] * spine
    f = []
    for k in range(pages):
        a = 2 * np.pi * k / pages
        base = len(v)
        for i in range(1, n):
            for z in zs:
                v.append([i / (n - 1) * np.cos(a), i / (n - 1) * np.sin(a), z])
                page.append(k)
        idx = lambda i, j: j if i == 0 else base + (i - 1) * spine + j  # noqa: E731
        for i in range(n - 1):
            for j in range(spine - 1):
                f += [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                      [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
    return np.array(v), np.array(f), np.array(page)


def numpy_edges(faces):
    """Unique undirected edges (a < b), sorted lexicographically."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


@pytest.fixture
def icosphere():
    return make_icosphere


@pytest.fixture
def grid():
    return make_grid


@pytest.fixture
def shared_mesh():
    """Returns the path of ../shared/meshes/<name>, skipping the test when it is absent."""

    def get(name):
        path = SHARED_MESHES / name
        if not path.exists():
            pytest.skip("{} not present".format(path))
        return path

    return get

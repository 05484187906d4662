"""Every method on every real mesh of ../shared/meshes, with the scenario and checks of
scripts/sweep_meshes.py (the lowest 8% along the longest axis fixed, the highest 8% turned
and moved; zero drag is rest, constraints met, converged, nothing flung away).

The sweep found three bugs no synthetic mesh showed: EigenDeformation's frames read from
rounding noise on the ogre (zero drag moved parts by 3 units), and ARAP and
LinearReconstruction refusing the whole beast for one non-manifold edge; its moved-scene check
(the same scene turned and shifted gives the moved result) found collinear triangles read as
slivers once turned (dk_triangle_degenerate). Here the moved-scene check runs on every other
pair of mesh and method (alternating along both, so that each method meets it on half the
meshes and each mesh with half the methods; the sweep script runs it on all). Marked heavy:
about two minutes, the sanitized run leaves it out.
"""
import importlib.util
import pathlib

import pytest

import deformkit as dk
from conftest import GROUP_METHODS, SHARED_MESHES

_SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "scripts" / "sweep_meshes.py"
_spec = importlib.util.spec_from_file_location("sweep_meshes", _SCRIPT)
sweep = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sweep)

MESH_FILES = sorted(p.name for p in SHARED_MESHES.glob("*")
                    if p.suffix in (".obj", ".off", ".ply")) if SHARED_MESHES.is_dir() else []

_cache = {}


def scenario(name):
    if name not in _cache:
        verts, sizes, idx = dk.load_mesh_file(str(SHARED_MESHES / name))
        mesh = dk.Mesh.from_polygons(verts, sizes, idx)
        _cache.clear()  # one mesh at a time: the parametrization runs mesh by mesh
        _cache[name] = (mesh,) + sweep.scenario(mesh)
    return _cache[name]


@pytest.mark.heavy
@pytest.mark.skipif(not MESH_FILES, reason="../shared/meshes not present")
@pytest.mark.parametrize("method", GROUP_METHODS)
@pytest.mark.parametrize("mesh_file", MESH_FILES)
def test_method_on_real_mesh(mesh_file, method):
    moved = (MESH_FILES.index(mesh_file) + GROUP_METHODS.index(method)) % 2 == 0
    status, detail = sweep.check(method, *scenario(mesh_file), moved=moved)
    assert status == "ok", "%s on %s: %s %s" % (method, mesh_file, status, detail)


POSE_METHODS = [m for m in GROUP_METHODS if "poses" in dk._native._method_info(m)["controls"]]


@pytest.mark.heavy
@pytest.mark.skipif(not MESH_FILES, reason="../shared/meshes not present")
@pytest.mark.parametrize("method", POSE_METHODS)
@pytest.mark.parametrize("mesh_file", MESH_FILES)
def test_poses_on_real_mesh(mesh_file, method):
    """A method that binds to poses, bound to a 270-degree twist of the mesh (the sweep's
    check_poses): poses and rest exact, half way finite and less stretched than the linear
    blend, the moved scene's in-between the moved one."""
    mesh, _, _, _, diag = scenario(mesh_file)
    status, detail = sweep.check_poses(method, mesh, diag)
    assert status == "ok", "%s on %s: %s %s" % (method, mesh_file, status, detail)

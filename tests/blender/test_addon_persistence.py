"""Save / reload / re-evaluate; the saved file renders the same without the add-on; Apply
(to the mesh, to a shape key) equals the evaluated result and removes the deformer."""
import os
import subprocess
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_addon_persistence")
TOL = 2e-5
BLEND = os.path.join(S.OUTPUT, "persist.blend")


def first_method():
    for m in S.methods.METHODS:
        if S.native.has_class(m.native_class):
            return m.id
    raise RuntimeError("no method class in the native module")


def test_save_reload():
    S.reset_scene()
    mid = first_method()
    obj, d, e, fixed, handle = S.grid_setup(mid)
    d.options_arap.max_iterations = 77
    bpy.ops.deformkit.bind()
    e.location = (1.0, 0.1, 0.45)
    bpy.context.view_layer.update()
    p1 = S.evaluated_positions(obj)
    bpy.ops.wm.save_as_mainfile(filepath=BLEND)
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    obj = bpy.data.objects["Grid"]
    d = obj.deformkit.deformers[0]
    R.check("settings survive reload", d.bound and d.fixed_group == "fixed"
            and d.options_arap.max_iterations == 77 and d.handles[0].target.name == "Tip"
            and d.method == mid)
    R.check("solver cache empty after load", len(S.solver.cache._cache) == 0)
    p2 = S.evaluated_positions(obj)
    R.check("reloaded file evaluates to the same result", np.abs(p2 - p1).max() < 1e-6,
            np.abs(p2 - p1).max())
    # dragging after reload rebuilds the solver on demand
    e = bpy.data.objects["Tip"]
    e.location.z += 0.2
    bpy.context.view_layer.update()
    p3 = S.evaluated_positions(obj)
    rest = S.rest_positions(obj)
    R.check("re-solves after reload", abs((p3 - p2)[handle, 2].mean() - 0.2) < 1e-4,
            (p3 - p2)[handle, 2].mean())
    R.check("status ok after reload", not d.status_is_error, d.status)
    e.location.z -= 0.2
    bpy.context.view_layer.update()
    p4 = S.evaluated_positions(obj)
    R.check("back to the saved pose (ARAP warm start: within 1e-3)", np.abs(p4 - p1).max() < 1e-3, np.abs(p4 - p1).max())


def test_renders_without_addon():
    """The saved file, opened by a Blender without the add-on, evaluates to the same mesh."""
    out = os.path.join(S.OUTPUT, "persist_noaddon.npy")
    if os.path.exists(out):
        os.remove(out)
    code = ("import bpy, numpy as np\n"
            "o = bpy.data.objects['Grid']\n"
            "dg = bpy.context.evaluated_depsgraph_get()\n"
            "me = o.evaluated_get(dg).to_mesh()\n"
            "co = np.empty(len(me.vertices)*3, np.float32); me.vertices.foreach_get('co', co)\n"
            "assert not hasattr(bpy.types.Object, 'deformkit')\n"
            "np.save(%r, co.reshape(-1, 3))\n" % out)
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    r = subprocess.run(S.blender_command(blend=BLEND, expr=code),
                       env=env, capture_output=True, text=True, timeout=120)
    if not R.check("Blender without the add-on opens the file", r.returncode == 0 and os.path.exists(out),
                   r.stdout[-500:] + r.stderr[-500:]):
        return
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    mine = S.evaluated_positions(bpy.data.objects["Grid"])
    other = np.load(out)
    R.check("same evaluated mesh without the add-on", np.abs(mine - other).max() < 1e-6,
            np.abs(mine - other).max())


def test_apply_mesh():
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    obj = bpy.data.objects["Grid"]
    d = obj.deformkit.deformers[0]
    attr = d.attribute_name
    bpy.context.view_layer.objects.active = obj
    want = S.evaluated_positions(obj)
    bpy.ops.deformkit.apply(mode="MESH")
    got = S.rest_positions(obj)
    R.check("apply writes the result into the mesh", np.abs(got - want).max() < TOL,
            np.abs(got - want).max())
    R.check("apply removes deformer, modifier and attribute",
            len(obj.deformkit.deformers) == 0 and len(obj.modifiers) == 0
            and obj.data.attributes.get(attr) is None)
    ev = S.evaluated_positions(obj)
    R.check("evaluated mesh unchanged by apply", np.abs(ev - want).max() < TOL)


def test_apply_shape_key():
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    obj = bpy.data.objects["Grid"]
    bpy.context.view_layer.objects.active = obj
    rest = S.rest_positions(obj)
    want = S.evaluated_positions(obj)
    bpy.ops.deformkit.apply(mode="SHAPE_KEY", keep=True)
    kb = obj.data.shape_keys.key_blocks
    R.check("shape key added", len(kb) == 2 and kb[1].name.startswith("DeformKit"), [k.name for k in kb])
    co = np.empty(len(rest) * 3, np.float32)
    kb[1].data.foreach_get("co", co)
    R.check("shape key holds the result", np.abs(co.reshape(-1, 3) - want).max() < TOL)
    R.check("base mesh untouched by shape-key apply", np.abs(S.rest_positions(obj) - rest).max() == 0)
    R.check("keep=True keeps the deformer", len(obj.deformkit.deformers) == 1)
    R.check("keep=True stores the key at value 0, as Blender's Save as Shape Key",
            kb[1].value == 0.0, kb[1].value)
    bpy.context.view_layer.update()
    shown = S.evaluated_positions(obj)
    R.check("keep=True: the result is shown once, not twice (the key and the deformer)",
            np.abs(shown - want).max() < TOL, np.abs(shown - want).max())
    try:
        bpy.ops.deformkit.apply(mode="MESH")
        R.check("apply to a mesh with shape keys refused", False)
    except RuntimeError as ex:
        R.check("apply to a mesh with shape keys refused with a message", "shape keys" in str(ex), ex)
    bpy.ops.deformkit.remove_deformer()
    kb[1].value = 1.0
    bpy.context.view_layer.update()
    R.check("the deformer removed and the key raised: the same result, from the key",
            np.abs(S.evaluated_positions(obj) - want).max() < TOL)


for t in (test_save_reload, test_renders_without_addon, test_apply_mesh, test_apply_shape_key):
    R.run(t)
R.finish()

"""Undo after Bind and after Apply (needs a window: run under
`xvfb-run -a blender --factory-startup --python tests/blender/test_addon_undo.py`).
Script-called operators do not push undo steps themselves (the UI does, after each operator),
so the test pushes one after each operator, as a click would."""
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_addon_undo")
MID = next((m.id for m in S.methods.METHODS if S.native.has_class(m.native_class)), "ARAP")


def push(msg):
    bpy.ops.ed.undo_push(message=msg)


def grid():
    return bpy.data.objects["Grid"]


def main():
    S.reset_scene()
    with bpy.context.temp_override(**S.ui_context()):
        obj, d, e, fixed, handle = S.grid_setup(MID)
        rest = S.rest_positions(obj)
        push("setup")
        bpy.ops.deformkit.bind()
        push("bind")
        R.check("bound", grid().deformkit.deformers[0].bound)
        bpy.ops.ed.undo()
        R.check("undo bind: not bound", not grid().deformkit.deformers[0].bound)
        R.check("undo bind: rest shape", np.abs(S.evaluated_positions(grid()) - rest).max() < 1e-6)
        bpy.ops.ed.redo()
        R.check("redo bind: bound", grid().deformkit.deformers[0].bound)
        e = bpy.data.objects["Tip"]
        e.location.z += 0.4
        bpy.context.view_layer.update()
        push("move")
        deformed = S.evaluated_positions(grid())
        R.check("deformed after move", abs((deformed - rest)[handle, 2].mean() - 0.4) < 1e-4)
        bpy.context.view_layer.objects.active = grid()
        bpy.ops.deformkit.apply(mode="MESH")
        push("apply")
        applied_err = np.abs(S.rest_positions(grid()) - deformed).max()
        R.check("applied into the mesh", applied_err < 2e-5
                and len(grid().deformkit.deformers) == 0, applied_err)
        bpy.ops.ed.undo()
        g = grid()
        R.check("undo apply: base mesh restored", np.abs(S.rest_positions(g) - rest).max() == 0)
        R.check("undo apply: deformer and modifier back", len(g.deformkit.deformers) == 1
                and S.geonodes.find_modifier(g, g.deformkit.deformers[0]) is not None)
        bpy.context.view_layer.update()
        p = S.evaluated_positions(g)
        R.check("undo apply: evaluated result back (re-solved, ARAP tolerance)", np.abs(p - deformed).max() < 1e-3, np.abs(p - deformed).max())
        d = g.deformkit.deformers[0]
        rt = S.solver.runtime.get((g.name, d.uid), {})
        if S.methods.get(d.method).iterative:
            # UI solves are budgeted; the first after an undo is not, so no partial pose shows
            R.check("undo apply: the first solve after undo is full and converged, not a "
                    "budgeted slice", rt and not rt.get("budgeted") and rt.get("converged")
                    and not S.solver.refining(g, d), rt)
        # the solver works after undo (cache re-validated, no stale bpy references)
        bpy.data.objects["Tip"].location.z -= 0.4
        bpy.context.view_layer.update()
        p = S.evaluated_positions(g)
        R.check("drag after undo re-solves", np.abs(p - rest).max() < 1e-4, np.abs(p - rest).max())


S.run_in_ui(main, R)

"""DeformKit: detail-preserving mesh deformation (ARAP, Laplacian editing, falloff) as
modifier-stack entries. The numerics live in the native `deformkit` module; this package only
maps Blender data to it. See docs/addon.md."""

bl_info = {
    "name": "DeformKit",
    "author": "DeformKit developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Modifiers > DeformKit; 3D View > Object > Add DeformKit Deformer",
    "description": "Detail-preserving deformers: ARAP, Laplacian editing, falloff",
    "category": "Mesh",
}

if "bpy" in locals():  # script reload
    import importlib
    for _m in (text, compat, methods, native, properties, geonodes, solver,  # noqa: F821
               handlers, pc2, bake, operators, make_controls, compute_weights, ui):  # noqa: F821
        importlib.reload(_m)

import bpy  # noqa: E402

from . import text, compat, methods, native, properties, geonodes, solver, handlers, pc2, bake  # noqa: E402
from . import operators, make_controls, compute_weights, overlay, ui  # noqa: E402

_modules = (properties, operators, make_controls, compute_weights, ui, handlers, overlay)


def register():
    native.load()
    if native.module is None:
        print("DeformKit:", native.error)
    for m in _modules:
        m.register()


def unregister():
    for m in reversed(_modules):
        m.unregister()

"""The few Blender API differences between the releases the add-on supports (3.4 to 5.x),
each behind one small function, so that the rest of the add-on reads the same everywhere.

- Node-group sockets: `NodeTree.inputs` / `outputs` until 3.6; `NodeTree.interface`
  (`new_socket`, `items_tree`) from 4.0, which removed the old collections.
- Built-in shader names: `UNIFORM_COLOR` in current releases; older ones know it only as
  `3D_UNIFORM_COLOR` (the prefixed names were deprecated, then removed in 4.0).

Checked and needing nothing here (docs/addon.md, "Blender versions"): the add-on reads no
F-curves (4.4's slotted actions, 5.0's removal of `Action.fcurves`), imports no OBJ through
Blender (4.0 removed `import_scene.obj`), and its materials name no renamed BSDF input.
"""

import bpy

VERSION = tuple(bpy.app.version)
HAS_INTERFACE = hasattr(bpy.types, "NodeTreeInterface")          # 4.0+


def new_group_socket(ng, name, in_out, socket_type):
    """Adds an input ('INPUT') or output ('OUTPUT') socket to a node group; returns it (the
    interface item from 4.0, which carries default_value, min_value and max_value as the
    old socket did)."""
    if HAS_INTERFACE:
        return ng.interface.new_socket(name=name, in_out=in_out, socket_type=socket_type)
    sockets = ng.inputs if in_out == "INPUT" else ng.outputs
    return sockets.new(socket_type, name)


def group_sockets(ng, in_out="INPUT"):
    """The node group's input (or output) sockets, in order: objects with .name and
    .identifier (the key of a Geometry Nodes modifier's input property)."""
    if HAS_INTERFACE:
        return [it for it in ng.interface.items_tree
                if getattr(it, "item_type", "SOCKET") == "SOCKET" and it.in_out == in_out]
    return list(ng.inputs if in_out == "INPUT" else ng.outputs)


def uniform_color_shader():
    """The built-in flat-colour shader for 3D lines and points (Show Graph)."""
    import gpu
    for name in ("UNIFORM_COLOR", "3D_UNIFORM_COLOR"):
        try:
            return gpu.shader.from_builtin(name)
        except (ValueError, TypeError):
            continue
    raise RuntimeError("no built-in uniform-colour shader in this Blender")

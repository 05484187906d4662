"""The few Blender API differences between the releases the add-on supports (3.4 to 5.x),
each behind one small function, so that the rest of the add-on reads the same everywhere.

- Node-group sockets: `NodeTree.inputs` / `outputs` until 3.6; `NodeTree.interface`
  (`new_socket`, `items_tree`) from 4.0, which removed the old collections.
- File-path properties holding "//" paths: the PATH_SUPPORTS_BLEND_RELATIVE option, known
  from 4.5 (BLEND_RELATIVE_PATH).
- Built-in shader names: `UNIFORM_COLOR` in current releases; older ones know it only as
  `3D_UNIFORM_COLOR` (the prefixed names were deprecated, then removed in 4.0).

- F-curves: `Action.fcurves` until 4.4; from 4.4 the slotted layout (layers, strips, channel
  bags), and 5.0 removed `Action.fcurves` (the panel's "animated, not baked" warning reads
  which paths an action animates).

- Mesh corners: from 3.6 a mesh's corner vertices and edges and its edge vertices are the
  hidden attributes ".corner_vert", ".corner_edge" and ".edge_verts", read at once with
  foreach_get; before, only through Mesh.loops and Mesh.edges, element by element (17 ms
  for the armadillo's 259k corners in 3.4): solver.quick_topology exists only from 3.6.
  The positions likewise: the "position" attribute from 3.6 (solver.rest_positions), where
  MeshVertex.co is 1-4 ms at 43k vertices in 4.2-5.0.

Checked and needing nothing here (docs/addon.md, "Blender versions"): the add-on imports no OBJ through
Blender (4.0 removed `import_scene.obj`), and its materials name no renamed BSDF input.
"""

import bpy

VERSION = tuple(bpy.app.version)
HAS_INTERFACE = hasattr(bpy.types, "NodeTreeInterface")          # 4.0+
CORNER_ATTRIBUTES = VERSION >= (3, 6, 0)                          # ".corner_vert" etc.
# File-path properties that may hold "//" (relative to the .blend) say so from 4.5 on (5.0
# warns on every such value without it); 4.2 and 3.4 do not know the flag and silently drop
# a property that names it.
BLEND_RELATIVE_PATH = {"PATH_SUPPORTS_BLEND_RELATIVE"} if VERSION >= (4, 5, 0) else set()


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


def action_animates(action, path):
    """Whether `action` has an F-curve for the RNA `path` (any array index)."""
    fcs = getattr(action, "fcurves", None)
    if fcs is not None:
        return any(fc.data_path == path for fc in fcs)
    for layer in getattr(action, "layers", ()):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", ()):
                if any(fc.data_path == path for fc in bag.fcurves):
                    return True
    return False

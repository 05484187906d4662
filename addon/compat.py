"""The few Blender API differences between the releases the add-on supports (3.4 to 5.3),
each behind one small function, so that the rest of the add-on reads the same everywhere.

- Geometry Nodes modifier inputs: ID properties on the modifier (`mod["Socket_1"]`) until
  5.1; from 5.2 RNA properties (`mod.properties.inputs.Socket_1.value`), and the modifier
  holds no ID properties at all (`mod[key]`, `mod.get`, `mod.keys()` raise TypeError). Their
  F-curve and driver paths change with them; files saved before 5.2 are versioned on load.

- Node-group sockets: `NodeTree.inputs` / `outputs` until 3.6; `NodeTree.interface`
  (`new_socket`, `items_tree`) from 4.0, which removed the old collections.
- File-path properties holding "//" paths: the PATH_SUPPORTS_BLEND_RELATIVE option, known
  from 4.5 (BLEND_RELATIVE_PATH).
- Built-in shaders: wide lines with `POLYLINE_UNIFORM_COLOR` (all releases), large points
  with `POINT_UNIFORM_COLOR` where it exists (5.3's Vulkan draws `UNIFORM_COLOR` points 1
  pixel wide), else `UNIFORM_COLOR` (the `3D_` prefixed names were removed in 4.0).

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
# 5.2+: a Geometry Nodes modifier's inputs are RNA properties under `properties.inputs`
MODIFIER_INPUTS_RNA = "properties" in bpy.types.NodesModifier.bl_rna.properties
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


def _input_item(mod, identifier):
    """5.2+: the modifier's RNA input struct for the group socket `identifier`, or None."""
    return getattr(mod.properties.inputs, identifier, None)


def modifier_input(mod, identifier, default=None):
    """The value of a Geometry Nodes modifier's input (`identifier`: the group socket's
    identifier), or `default` when the modifier has no such input."""
    if MODIFIER_INPUTS_RNA:
        item = _input_item(mod, identifier)
        return default if item is None else item.value
    return mod.get(identifier, default)


def set_modifier_input(mod, identifier, value):
    """Writes a Geometry Nodes modifier's input and has the object re-evaluated (an ID
    property written behind RNA's back re-evaluates nothing by itself). Returns True when the
    value changed. KeyError when the modifier has no such input (5.2+: its group lacks it)."""
    if modifier_input(mod, identifier) == value:
        return False
    if MODIFIER_INPUTS_RNA:
        item = _input_item(mod, identifier)
        if item is None:
            raise KeyError(identifier)
        item.value = value
    else:
        mod[identifier] = value
    mod.id_data.update_tag()
    return True


def modifier_input_prop(mod, identifier):
    """(owner, property name) of a modifier's input, for layout.prop and keyframe_insert."""
    if MODIFIER_INPUTS_RNA:
        item = _input_item(mod, identifier)
        if item is None:
            raise KeyError(identifier)
        return item, "value"
    return mod, '["%s"]' % bpy.utils.escape_identifier(identifier)


def modifier_input_path(mod, identifier):
    """The RNA path of a modifier's input from its object (F-curves and drivers)."""
    name = bpy.utils.escape_identifier(mod.name)
    if MODIFIER_INPUTS_RNA:
        return 'modifiers["%s"].properties.inputs.%s.value' % (name, identifier)
    return 'modifiers["%s"]["%s"]' % (name, bpy.utils.escape_identifier(identifier))


def watch_modifier_input(mod, identifier, owner, notify):
    """Has Blender call notify() after an edit in the UI of the input `identifier` of `mod`
    or of any modifier with the same node group. For 5.2, whose RNA input properties carry no
    update: an edit there re-evaluates nothing by itself (a write from Python neither; 5.3
    re-evaluates both). Cleared with bpy.msgbus.clear_by_owner(owner), and by Blender on
    file load. Returns whether it subscribed: before 5.2 an input is an ID property, whose UI
    edit re-evaluates the object, and there is nothing to watch."""
    if not MODIFIER_INPUTS_RNA:
        return False
    item = _input_item(mod, identifier)
    if item is None:
        return False
    # the input structs are typed per node group and socket: one subscription covers every
    # modifier of the group
    bpy.msgbus.subscribe_rna(key=(type(item), "value"), owner=owner, args=(), notify=notify)
    return True


def _builtin_shader(*names):
    import gpu
    for name in names:
        try:
            return gpu.shader.from_builtin(name)
        except (ValueError, TypeError):
            continue
    raise RuntimeError("none of the built-in shaders %s in this Blender" % (names,))


def point_shader():
    """The built-in flat-colour shader for large 3D points (Show Graph's nodes):
    POINT_UNIFORM_COLOR where it exists (4.x+: with UNIFORM_COLOR, 5.3's Vulkan backend draws
    every point 1 pixel wide whatever gpu.state.point_size_set says, and newer releases warn
    that drawing points with it is deprecated); UNIFORM_COLOR in 3.4."""
    return _builtin_shader("POINT_UNIFORM_COLOR", "UNIFORM_COLOR", "3D_UNIFORM_COLOR")


def line_shader():
    """The built-in flat-colour shader for wide 3D lines (Show Graph's edges):
    POLYLINE_UNIFORM_COLOR, in every supported release (3D_POLYLINE_UNIFORM_COLOR, its
    older name, as a fallback). It takes the width and the viewport size as uniforms
    ("lineWidth", "viewportSize"); UNIFORM_COLOR ignores gpu.state.line_width_set on
    Vulkan and Metal and is deprecated for wide lines."""
    return _builtin_shader("POLYLINE_UNIFORM_COLOR", "3D_POLYLINE_UNIFORM_COLOR")


def painting():
    """Whether a paint stroke is running now (a modal PAINT_OT_* operator in a window): from
    4.2, Window.modal_operators lists them; before, None (unknown)."""
    wm = getattr(bpy.context, "window_manager", None)
    if wm is None:
        return False
    if not len(wm.windows) or not hasattr(wm.windows[0], "modal_operators"):
        return None
    for win in wm.windows:
        for op in win.modal_operators:
            if getattr(op, "bl_idname", "").startswith(("PAINT_OT", "paint.")):
                return True
    return False


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

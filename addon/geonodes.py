"""The Geometry Nodes modifier each deformer owns.

One shared node group, saved in the .blend (so files render without the add-on):
    Group Input (Geometry, Factor, Attribute name, Input name)
      -> Store Named Attribute (Position as "Input name")      (version 2)
      -> Set Position (Offset = Named Attribute "Attribute name" SCALE by Factor) -> Output
Each deformer writes its offset (result - input) into its own point attribute
"dk_<uid>_offset" of the base mesh; its modifier's Attribute input names it, which is also how
the add-on finds the modifier again (modifiers may be renamed and reordered freely).

The stored input ("dk_<uid>_input" on the evaluated mesh) is what reaches the modifier: the
base mesh moved by the modifiers and shape keys above it. A method that follows an animated
input (Embedded Deformation, section 5 of Sumner et al.) reads it back from the evaluated
object each update (animated_input.moved_input). Version 1 groups (files saved before) are upgraded
in place: the three first sockets keep their identifiers, so values and keyframes survive.
"""

import bpy

from . import compat

GROUP_NAME = "DeformKit Offset"
GROUP_VERSION = 2


def _socket_id(ng, name):
    for s in compat.group_sockets(ng, "INPUT"):
        if s.name == name:
            return s.identifier
    raise KeyError(name)


def _hide_plumbing(ng):
    """Keeps the group's inputs out of the modifier's panel where Blender can (4.0+:
    hide_in_modifier). Editing the attribute names there would unlink the deformer, and the
    Factor is the DeformKit panel's. Blender 3.4-3.6 have no such flag: the inputs show
    there, and a deformer whose Attribute was edited is found again by its modifier's name
    (find_modifier) and repaired (repair). Idempotent; the group's version is unchanged, so
    files stay readable in every supported Blender."""
    for sock in compat.group_sockets(ng, "INPUT"):
        if hasattr(sock, "hide_in_modifier") and sock.name in ("Factor", "Attribute", "Input") \
                and not sock.hide_in_modifier:
            sock.hide_in_modifier = True


def ensure_node_group():
    ng = bpy.data.node_groups.get(GROUP_NAME)
    if ng is not None and ng.bl_idname == "GeometryNodeTree":
        version = ng.get("deformkit_version")
        if version == GROUP_VERSION:
            _hide_plumbing(ng)
            return ng
        if version == 1:
            _add_input_capture(ng)
            ng["deformkit_version"] = GROUP_VERSION
            _hide_plumbing(ng)
            return ng
    if ng is not None:  # a foreign group with our name: leave it, make ours under a new name
        ng.name = GROUP_NAME + ".old"
    ng = bpy.data.node_groups.new(GROUP_NAME, "GeometryNodeTree")
    ng["deformkit_version"] = GROUP_VERSION
    compat.new_group_socket(ng, "Geometry", "INPUT", "NodeSocketGeometry")
    f = compat.new_group_socket(ng, "Factor", "INPUT", "NodeSocketFloat")
    f.default_value = 1.0
    f.min_value = -10.0
    f.max_value = 10.0
    compat.new_group_socket(ng, "Attribute", "INPUT", "NodeSocketString")
    compat.new_group_socket(ng, "Geometry", "OUTPUT", "NodeSocketGeometry")
    nodes, links = ng.nodes, ng.links
    gin = nodes.new("NodeGroupInput")
    gin.location = (-600, 0)
    gout = nodes.new("NodeGroupOutput")
    gout.location = (300, 0)
    attr = nodes.new("GeometryNodeInputNamedAttribute")
    attr.data_type = "FLOAT_VECTOR"
    attr.location = (-350, -150)
    scale = nodes.new("ShaderNodeVectorMath")
    scale.operation = "SCALE"
    scale.location = (-150, -150)
    setpos = nodes.new("GeometryNodeSetPosition")
    setpos.location = (80, 0)
    attr_out = [o for o in attr.outputs if o.type == "VECTOR" and o.enabled][0]
    links.new(gin.outputs["Attribute"], attr.inputs["Name"])
    links.new(attr_out, scale.inputs[0])
    links.new(gin.outputs["Factor"], scale.inputs["Scale"])
    links.new(gin.outputs["Geometry"], setpos.inputs["Geometry"])
    links.new(scale.outputs["Vector"], setpos.inputs["Offset"])
    links.new(setpos.outputs["Geometry"], gout.inputs["Geometry"])
    _add_input_capture(ng)
    _hide_plumbing(ng)
    return ng


def _add_input_capture(ng):
    """Version 2: the "Input" socket, and a Store Named Attribute of the incoming positions
    between the Group Input and the Set Position."""
    compat.new_group_socket(ng, "Input", "INPUT", "NodeSocketString")
    nodes, links = ng.nodes, ng.links
    gin = next(n for n in nodes if n.bl_idname == "NodeGroupInput")
    setpos = next(n for n in nodes if n.bl_idname == "GeometryNodeSetPosition")
    store = nodes.new("GeometryNodeStoreNamedAttribute")
    store.data_type = "FLOAT_VECTOR"
    store.domain = "POINT"
    store.location = (-150, 150)
    position = nodes.new("GeometryNodeInputPosition")
    position.location = (-350, 250)
    value = [i for i in store.inputs if i.name == "Value" and i.type == "VECTOR" and i.enabled][0]
    links.new(gin.outputs["Geometry"], store.inputs["Geometry"])
    links.new(gin.outputs["Input"], store.inputs["Name"])
    links.new(position.outputs[0], value)
    links.new(store.outputs["Geometry"], setpos.inputs["Geometry"])


def factor_key(ng=None):
    ng = ng or ensure_node_group()
    return _socket_id(ng, "Factor")


def attribute_key(ng=None):
    ng = ng or ensure_node_group()
    return _socket_id(ng, "Attribute")


def input_key(ng=None):
    ng = ng or ensure_node_group()
    return _socket_id(ng, "Input")


def is_ours(mod):
    ng = getattr(mod, "node_group", None)
    return (mod.type == "NODES" and ng is not None and ng.get("deformkit_version") is not None)


def _attribute_of(mod):
    try:
        return compat.modifier_input(mod, _socket_id(mod.node_group, "Attribute"))
    except KeyError:
        return None


def find_modifier(obj, deformer):
    """The GN modifier owned by `deformer`: matched by its Attribute input, else (that input
    edited by hand) by the modifier name recorded at creation, when that modifier's
    Attribute names no deformer of `obj`. None when there is none. Read-only (panels call
    it): repair() puts an edited Attribute back."""
    want = deformer.attribute_name
    by_name = None
    for mod in obj.modifiers:
        if is_ours(mod):
            a = _attribute_of(mod)
            if a == want:
                return mod
            if deformer.modifier_name and mod.name == deformer.modifier_name:
                by_name = mod
    if by_name is not None:
        if _attribute_of(by_name) in {x.attribute_name for x in obj.deformkit.deformers}:
            return None  # another deformer's modifier that took the name
    return by_name


def repair(mod, deformer):
    """Puts the modifier's Attribute input back if it was edited, and records the
    modifier's current name (the user may rename it). Not for draw code (it writes)."""
    compat.set_modifier_input(mod, attribute_key(mod.node_group), deformer.attribute_name)
    if deformer.modifier_name != mod.name:
        deformer.modifier_name = mod.name


def ensure_modifier(obj, deformer):
    """The deformer's modifier, created (at the end of the stack) or repaired."""
    mod = find_modifier(obj, deformer)
    if mod is None:
        ng = ensure_node_group()
        mod = obj.modifiers.new(deformer.name, "NODES")
        mod.node_group = ng
        compat.set_modifier_input(mod, factor_key(ng), 1.0)
        compat.set_modifier_input(mod, attribute_key(ng), deformer.attribute_name)
        made = True
    else:
        made = False
        if mod.node_group.name == GROUP_NAME:
            _hide_plumbing(mod.node_group)
    repair(mod, deformer)
    ensure_input_name(mod, deformer)
    if made:
        watch_factor_edits()
    return mod


# owner of the message-bus subscriptions of watch_factor_edits (cleared and made anew there)
_WATCH_OWNER = object()


def _factor_edited():
    """A Factor was edited in the UI: re-evaluates every object with a DeformKit modifier
    (only the Geometry Nodes offset runs again; no solve)."""
    for obj in bpy.data.objects:
        if any(is_ours(m) for m in getattr(obj, "modifiers", ())):
            obj.update_tag()


def watch_factor_edits():
    """Subscribes _factor_edited to edits of the Factor of each DeformKit node group in the
    file (compat.watch_modifier_input: needed in 5.2, harmless after). Called on load, undo
    and redo, on registration, and when a modifier is made. Returns how many groups are
    watched."""
    bpy.msgbus.clear_by_owner(_WATCH_OWNER)
    watched = set()
    for obj in bpy.data.objects:
        for mod in getattr(obj, "modifiers", ()):
            if is_ours(mod) and mod.node_group.name not in watched:
                try:
                    key = factor_key(mod.node_group)
                except KeyError:
                    continue
                if compat.watch_modifier_input(mod, key, _WATCH_OWNER, _factor_edited):
                    watched.add(mod.node_group.name)
    return len(watched)


def ensure_input_name(mod, deformer):
    """Sets the modifier's Input name (upgrading a version 1 group first). True when the
    modifier now stores its input."""
    ng = mod.node_group
    if ng.get("deformkit_version") != GROUP_VERSION:
        if ng.name != GROUP_NAME:
            return False  # a renamed or foreign copy: leave it
        ng = ensure_node_group()
    compat.set_modifier_input(mod, input_key(ng), deformer.input_attribute_name)
    return True


def factor(obj, deformer):
    mod = find_modifier(obj, deformer)
    if mod is None:
        return 1.0
    return float(compat.modifier_input(mod, factor_key(mod.node_group), 1.0))


def set_factor(mod, value):
    """Sets the modifier's Factor (and has the object re-evaluated)."""
    compat.set_modifier_input(mod, factor_key(mod.node_group), float(value))


def factor_prop(mod):
    """(owner, property name) of the modifier's Factor: for layout.prop and keyframe_insert."""
    return compat.modifier_input_prop(mod, factor_key(mod.node_group))


def factor_data_path(mod):
    """RNA path of the modifier's Factor from its object (its F-curves and drivers)."""
    return compat.modifier_input_path(mod, factor_key(mod.node_group))


def ensure_attribute(mesh, name):
    a = mesh.attributes.get(name)
    if a is not None and (a.data_type != "FLOAT_VECTOR" or a.domain != "POINT"):
        mesh.attributes.remove(a)
        a = None
    if a is None:
        a = mesh.attributes.new(name, "FLOAT_VECTOR", "POINT")
    return a


def remove_attribute(mesh, name):
    a = mesh.attributes.get(name)
    if a is not None:
        mesh.attributes.remove(a)

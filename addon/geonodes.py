"""The Geometry Nodes modifier each deformer owns.

One shared node group, saved in the .blend (so files render without the add-on):
    Group Input (Geometry, Factor, Attribute name)
      -> Named Attribute (FLOAT_VECTOR, name = input) -> Vector Math SCALE by Factor
      -> Set Position (Offset) -> Group Output
Each deformer writes its offset (result - rest) into its own point attribute
"dk_<uid>_offset" of the base mesh; its modifier's Attribute input names it, which is also how
the add-on finds the modifier again (modifiers may be renamed and reordered freely).
"""

import bpy

from . import compat

GROUP_NAME = "DeformKit Offset"
GROUP_VERSION = 1


def _socket_id(ng, name):
    for s in compat.group_sockets(ng, "INPUT"):
        if s.name == name:
            return s.identifier
    raise KeyError(name)


def ensure_node_group():
    ng = bpy.data.node_groups.get(GROUP_NAME)
    if ng is not None and ng.get("deformkit_version") == GROUP_VERSION and ng.bl_idname == "GeometryNodeTree":
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
    return ng


def factor_key(ng=None):
    ng = ng or ensure_node_group()
    return _socket_id(ng, "Factor")


def attribute_key(ng=None):
    ng = ng or ensure_node_group()
    return _socket_id(ng, "Attribute")


def is_ours(mod):
    ng = getattr(mod, "node_group", None)
    return (mod.type == "NODES" and ng is not None and ng.get("deformkit_version") is not None)


def find_modifier(obj, deformer):
    """The GN modifier owned by `deformer` (matched by attribute name), or None."""
    want = deformer.attribute_name
    for mod in obj.modifiers:
        if is_ours(mod):
            try:
                if mod[_socket_id(mod.node_group, "Attribute")] == want:
                    return mod
            except KeyError:
                continue
    return None


def ensure_modifier(obj, deformer):
    mod = find_modifier(obj, deformer)
    if mod is not None:
        return mod
    ng = ensure_node_group()
    mod = obj.modifiers.new(deformer.name, "NODES")
    mod.node_group = ng
    mod[factor_key(ng)] = 1.0
    mod[attribute_key(ng)] = deformer.attribute_name
    return mod


def factor(obj, deformer):
    mod = find_modifier(obj, deformer)
    if mod is None:
        return 1.0
    return float(mod[factor_key(mod.node_group)])


def factor_path(mod):
    """RNA path of the modifier's Factor input (for layout.prop and keyframes)."""
    return '["%s"]' % factor_key(mod.node_group)


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

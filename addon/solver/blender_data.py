"""Reading the mesh from Blender (positions, triangles, vertex groups) and writing the
deformer's result into its point attribute. The base mesh positions are never written."""

import bpy
import numpy as np

from .. import compat, geonodes, methods
from ..errors import DeformKitError
from ..text import article


def check_mesh_type(obj):
    if obj.type != "MESH":
        raise DeformKitError("DeformKit deforms mesh objects; '%s' is %s"
                             % (obj.name, article(obj.type.lower().replace("_", " "))))


def check_object(obj, d=None):
    if obj is None:
        raise DeformKitError("no active object")
    check_mesh_type(obj)
    me = obj.data
    if len(me.vertices) == 0:
        raise DeformKitError("mesh '%s' has no vertices" % me.name)
    needs_faces = d is None or methods.get(d.method).needs_faces
    if len(me.polygons) == 0 and needs_faces:
        raise DeformKitError("mesh '%s' has no faces: this method needs a surface (Embedded "
                             "Deformation also deforms vertex clouds)" % me.name)
    if obj.mode == "EDIT":
        raise DeformKitError("'%s' is in Edit Mode: leave it to bind or solve" % obj.name)


def evaluated_positions(obj):
    """The object's evaluated (modifier stack applied) vertex positions, object space."""
    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64)


def rest_positions(me):
    """The base mesh's positions (n x 3 float64). From 3.6 through the "position" attribute:
    0.04 ms at 43k vertices where MeshVertex.co takes 1-4 ms in 4.2-5.0, and every solve
    compares them with the binding's."""
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    a = me.attributes.get("position") if compat.CORNER_ATTRIBUTES else None
    if a is not None and a.domain == "POINT" and a.data_type == "FLOAT_VECTOR":
        a.data.foreach_get("vector", co)
    else:
        me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def triangles(me):
    me.calc_loop_triangles()
    tri = np.empty(len(me.loop_triangles) * 3, dtype=np.int32)
    me.loop_triangles.foreach_get("vertices", tri)
    return tri.reshape(-1, 3)


def read_groups(obj, names):
    """{group name: (indices int32, weights float64)} for the existing groups in `names`;
    members are vertices with weight > 0. One pass over the vertices."""
    by_index = {}
    for n in names:
        vg = obj.vertex_groups.get(n)
        if vg is not None:
            by_index[vg.index] = n
    idx = {n: [] for n in by_index.values()}
    wts = {n: [] for n in by_index.values()}
    if by_index:
        for v in obj.data.vertices:
            for g in v.groups:
                n = by_index.get(g.group)
                if n is not None and g.weight > 0.0:
                    idx[n].append(v.index)
                    wts[n].append(g.weight)
    return {n: (np.array(idx[n], dtype=np.int32), np.array(wts[n], dtype=np.float64))
            for n in idx}


def check_editable(obj):
    """DeformKitError when `obj` or its mesh is linked from a library: nothing the add-on
    writes (the deformer's settings, its result attribute, an applied mesh) can be stored
    there, and Bind and Apply reported success having written nothing, Apply even removing
    the deformer (the second hostile review)."""
    lib = obj.library
    if lib is not None:
        raise DeformKitError("'%s' is linked from the library '%s': DeformKit cannot change it "
                             "here (make it local: Object > Relations > Make Local)"
                             % (obj.name, lib.name))
    lib = getattr(obj.data, "library", None)
    if lib is not None:
        raise DeformKitError("the mesh '%s' of '%s' is linked from the library '%s': DeformKit "
                             "cannot change it here (make it local: Object > Relations > Make "
                             "Local > Object and Data)" % (obj.data.name, obj.name, lib.name))


def write_offset(obj, d, offset, retime=False, sim_key=""):
    """The deformer's result (offset from its input, n x 3) into its attribute; `sim_key`:
    the simulated frame it is (solving._sim_key), "" for anything else."""
    me = obj.data
    a = geonodes.ensure_attribute(me, d.attribute_name)
    a.data.foreach_set("vector", np.ascontiguousarray(offset, dtype=np.float32).ravel())
    if d.sim_frame_key != sim_key:
        d.sim_frame_key = sim_key
    me.update_tag()
    if retime:
        # Frame change: a depsgraph re-evaluated after this tag (a render's, see handlers.py)
        # re-copies the object from the original, whose animated values (the modifier's
        # Factor) are not flushed there; re-run the object's animation with it.
        obj.update_tag(refresh={"TIME"})


def zero_offset(obj, d):
    me = obj.data
    a = me.attributes.get(d.attribute_name)
    if d.sim_frame_key:
        d.sim_frame_key = ""
    if a is not None and len(a.data) == len(me.vertices):
        a.data.foreach_set("vector", np.zeros(len(me.vertices) * 3, dtype=np.float32))
        me.update_tag()

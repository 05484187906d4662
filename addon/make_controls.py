"""Make Lattice and Make Cage: a control object fitted around the mesh (or, in Edit Mode, its
selected vertices), parented to the mesh so that moving the mesh moves both, and set as the
active deformer's control. The fit reads the mesh's rest positions, where Bind registers it."""

import bmesh
import bpy
import numpy as np
from bpy.props import FloatProperty, IntProperty, IntVectorProperty
from mathutils import Matrix

from . import solver
from .enclosing_cage import enclosing_cage
from .operators import _Base, _get_deformer, _get_object
from .text import plural

# the lattice's box around the points: this part of each side beyond them (and of the
# diagonal, so that a flat selection gets a box too); the native Lattice's default box
LATTICE_MARGIN = 0.05


def fit_points(obj):
    """The rest positions Make fits (n x 3, object space): the selected vertices in Edit
    Mode when there are any, else every vertex."""
    if obj.mode == "EDIT":
        bm = bmesh.from_edit_mesh(obj.data)
        sel = [v.co[:] for v in bm.verts if v.select]
        if sel:
            return np.array(sel, dtype=np.float64)
        return np.array([v.co[:] for v in bm.verts], dtype=np.float64).reshape(-1, 3)
    return solver.rest_positions(obj.data)


def _control_deformer(op, context, kind):
    obj = _get_object(op, context)
    d = _get_deformer(op, context, obj)
    c = solver.controls.of(d)
    if c.uses_handles or c.KIND != kind:
        raise solver.DeformKitError("%s is not driven by a %s: add a %s deformer first"
                                    % (d.name, kind, kind.title()))
    P = fit_points(obj)
    if len(P) == 0:
        raise solver.DeformKitError("'%s' has no vertices to fit a %s to" % (obj.name, kind))
    return obj, d, P


def _place(obj, new, name):
    """Links `new` where obj is, parented to it (its local space is obj's)."""
    cols = obj.users_collection or (bpy.context.scene.collection,)
    cols[0].objects.link(new)
    new.parent = obj
    new.matrix_parent_inverse = Matrix.Identity(4)
    new.name = name
    return new


class DEFORMKIT_OT_make_lattice(_Base, bpy.types.Operator):
    """Fit a Lattice object around the mesh (in Edit Mode: the selection), parented to it, and
    make it the deformer's lattice"""
    bl_idname = "deformkit.make_lattice"
    bl_label = "Make Lattice"
    bl_options = {"REGISTER", "UNDO"}
    resolution: IntVectorProperty(name="Points", size=3, default=(3, 3, 3), min=2, max=64,
                                  description="Lattice points along x, y and z")

    def run(self, context):
        obj, d, P = _control_deformer(self, context, "lattice")
        lo, hi = P.min(axis=0), P.max(axis=0)
        grow = LATTICE_MARGIN * (hi - lo) + 1e-3 * max(float(np.linalg.norm(hi - lo)), 1e-6)
        lo, hi = lo - grow, hi + grow
        lt = bpy.data.lattices.new(obj.name + " Lattice")
        lt.points_u, lt.points_v, lt.points_w = self.resolution
        co = np.array([p.co[:] for p in lt.points])
        clo, chi = co.min(axis=0), co.max(axis=0)
        # the lattice's own box [clo, chi] onto [lo, hi], in the mesh's space
        s = (hi - lo) / (chi - clo)
        M = Matrix.Identity(4)
        for a in range(3):
            M[a][a] = s[a]
            M[a][3] = lo[a] - s[a] * clo[a]
        ob = _place(obj, bpy.data.objects.new(obj.name + " Lattice", lt),
                    obj.name + " Lattice")
        ob.matrix_basis = M
        d.control_object = ob
        self.report({"INFO"}, "Made lattice '%s' (points %d x %d x %d): press Bind"
                    % ((ob.name,) + tuple(self.resolution)))


class DEFORMKIT_OT_make_cage(_Base, bpy.types.Operator):
    """Build a coarse closed cage around the mesh (in Edit Mode: the selection), parented to
    it, and make it the deformer's cage"""
    bl_idname = "deformkit.make_cage"
    bl_label = "Make Cage"
    bl_options = {"REGISTER", "UNDO"}
    detail: IntProperty(name="Detail", default=2, min=0, max=4,
                        description="Subdivisions of the cage's sphere: 0-4 give 12, 42, 162, "
                                    "642 and 2562 cage vertices")
    margin: FloatProperty(name="Margin", default=0.05, min=0.0, max=10.0,
                          description="How far outside the mesh the cage stays, as a part of "
                                      "each point's distance from the cage's centre")

    def run(self, context):
        obj, d, P = _control_deformer(self, context, "cage")
        V, F = enclosing_cage(P, self.detail, self.margin)
        me = bpy.data.meshes.new(obj.name + " Cage")
        me.from_pydata([tuple(v) for v in V], [], [tuple(int(i) for i in f) for f in F])
        me.update()
        ob = _place(obj, bpy.data.objects.new(obj.name + " Cage", me), obj.name + " Cage")
        ob.display_type = "WIRE"
        ob.hide_render = True
        d.control_object = ob
        self.report({"INFO"}, "Made cage '%s' (%s): press Bind"
                    % (ob.name, plural(len(V), "vertex")))


CLASSES = [DEFORMKIT_OT_make_lattice, DEFORMKIT_OT_make_cage]


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)

"""Which collector reads a deformer's controls from Blender: chosen by the control kinds its
native method declares (deformkit._native._method_info(name)["controls"], from the method's
table, dk_method_ops.controls), never by the method's name. A collector is a module with
    uses_handles      -> True: the deformer's handles (vertex groups moved by targets) are
                         its controls; False: a control object (d.control_object) is
    capture(obj, d, depsgraph) -> what Bind keeps of the controls now (None: nothing)
    store(d, captured)         -> keeps it in the deformer (Bind's end, on success)
    collect(obj, d, captured=None)
                      -> (the bind's keywords, bytes that change when the controls do),
                         from `captured` or what the deformer keeps; raises DeformKitError
                         naming what is missing or wrong
    settings_key(d)   -> what of d's settings (besides the controls) its binding depends on
    exist(obj, d)     -> whether every control d names is still there (cheap: every solve)
and, for a control object (uses_handles False), KIND, LABEL, OBJECT_TYPE, MAKE_OPERATOR (the
operator the panel offers under it: the one that makes a lattice or cage around the mesh, or
the one that computes the bones' weights into their groups), SOLVE_KEYWORD and
    targets(obj, d, e, depsgraph) -> the control's points on this frame (n_controls x 3),
                                     or its bones' frames (n_controls x 4 x 4)
    summary(d), missing(d)        -> the status line's words
Vertex groups of the deformed mesh (vertex_groups.py), a Blender Lattice object
(lattice_control.py), a closed mesh as a cage (cage_control.py) and an Armature's bones
(bones_control.py)."""

from .. import methods, native
from ..errors import DeformKitError
from . import bones_control, cage_control, lattice_control, vertex_groups

COLLECTORS = {"vertex_groups": vertex_groups, "lattice": lattice_control, "cage": cage_control,
              "bones": bones_control}


def kinds(m):
    """The control kinds method `m`'s native class binds to; vertex groups when the module
    does not say (a build without the contract's controls, the tests' mock module)."""
    return native.control_kinds(m.native_class)


def collector(m):
    """The collector for the first of m's control kinds that the add-on reads."""
    ks = kinds(m)
    for k in ks:
        c = COLLECTORS.get(k)
        if c is not None:
            return c
    raise DeformKitError("%s binds to %s, which this version of the add-on cannot read from "
                         "Blender" % (m.label, " or ".join(k.replace("_", " ") for k in ks)))


def of(d):
    """The collector of deformer d's method."""
    return collector(methods.get(d.method))


def uses_handles(d):
    """Whether d's controls are its handles (else a control object); True for a method
    whose kinds the add-on cannot read (its collect raises)."""
    try:
        return of(d).uses_handles
    except DeformKitError:
        return True


def capture(obj, d, depsgraph=None):
    return of(d).capture(obj, d, depsgraph)


def store(d, captured):
    of(d).store(d, captured)


def collect(obj, d, captured=None):
    return of(d).collect(obj, d, captured)


def settings_key(d):
    return collector(methods.get(d.method)).settings_key(d)


def exist(obj, d):
    return collector(methods.get(d.method)).exist(obj, d)

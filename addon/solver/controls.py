"""Which collector reads a deformer's controls from Blender: chosen by the control kinds its
native method declares (deformkit._native._method_info(name)["controls"], from the method's
table, dk_method_ops.controls), never by the method's name. A collector is a module with
    collect(obj, d)   -> (the bind's keywords, bytes that change when the controls do);
                         raises DeformKitError naming what is missing or wrong
    settings_key(d)   -> what of d's settings (besides the controls) its binding depends on
    exist(obj, d)     -> whether every control d names is still there (cheap: every solve)
The add-on reads one kind so far, vertex groups of the deformed mesh (vertex_groups.py);
a lattice or a cage adds its module to COLLECTORS."""

from .. import methods, native
from ..errors import DeformKitError
from . import vertex_groups

COLLECTORS = {"vertex_groups": vertex_groups}


def kinds(m):
    """The control kinds method `m`'s native class binds to; vertex groups when the module
    does not say (a build without the contract's controls, the tests' mock module)."""
    return tuple(native.method_info(m.native_class).get("controls") or ("vertex_groups",))


def collector(m):
    """The collector for the first of m's control kinds that the add-on reads."""
    ks = kinds(m)
    for k in ks:
        c = COLLECTORS.get(k)
        if c is not None:
            return c
    raise DeformKitError("%s binds to %s, which this version of the add-on cannot read from "
                         "Blender" % (m.label, " or ".join(k.replace("_", " ") for k in ks)))


def collect(obj, d):
    return collector(methods.get(d.method)).collect(obj, d)


def settings_key(d):
    return collector(methods.get(d.method)).settings_key(d)


def exist(obj, d):
    return collector(methods.get(d.method)).exist(obj, d)

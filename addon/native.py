"""Finds the native `deformkit` module.

Order: a `deformkit` package inside the add-on folder (how the legacy zip ships it), then
`deformkit` on sys.path: the wheel that Blender 4.2+ installs from the extension zip, a
`pip install` into Blender's Python, or the build tree (PYTHONPATH=build/python). The add-on's
own package is `deformkit_addon`, so it cannot shadow the module; a `deformkit` without `Mesh`
(some other package of that name) is still rejected.
"""

import importlib
import sys

module = None
error = ""


def load():
    global module, error
    if module is not None:
        return module
    errors = []
    pkg = __package__
    candidates = [pkg + ".deformkit"] if pkg else []
    candidates.append("deformkit")
    for name in candidates:
        try:
            m = importlib.import_module(name)
        except ImportError as e:
            errors.append("%s: %s" % (name, e))
            continue
        if hasattr(m, "Mesh"):
            module = m
            error = ""
            return m
        errors.append("%s: found but has no Mesh (not the native module)" % name)
    error = ("DeformKit native module not found (%s); install the packaged add-on zip or put "
             "build/python on PYTHONPATH (python %d.%d)" % ("; ".join(errors), *sys.version_info[:2]))
    return None


def get():
    """The module, or raises RuntimeError with a clear message."""
    m = load()
    if m is None:
        raise RuntimeError(error)
    return m


def has_class(name):
    m = load()
    return m is not None and hasattr(m, name)


def method_info(name):
    """The native contract's flags of method class `name` (deformkit._native._method_info:
    iterative, edits_input, ...), {} when the module or the method is missing."""
    m = load()
    try:
        return dict(m._native._method_info(name)) if m is not None else {}
    except (AttributeError, KeyError):
        return {}


def control_kinds(name):
    """The control kinds method class `name` binds to (its table's dk_method_ops.controls:
    "vertex_groups", "lattice", "cage", ...); vertex groups when the module does not say (a
    build without the contract's controls, the tests' mock module)."""
    return tuple(method_info(name).get("controls") or ("vertex_groups",))

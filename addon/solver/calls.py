"""Calling the native module: its errors become DeformKitError naming what failed."""

from .. import native
from ..errors import DeformKitError


NATIVE_ERRORS = (ValueError, IndexError, TypeError, RuntimeError, MemoryError, OverflowError)


def _native_call(what, fn, *a, **kw):
    try:
        return fn(*a, **kw)
    except DeformKitError:
        raise
    except NATIVE_ERRORS as e:
        raise DeformKitError("%s: %s" % (what, e)) from e


def _native_class(m):
    dk = native.load()
    if dk is None:
        raise DeformKitError(native.error)
    cls = getattr(dk, m.native_class, None)
    if cls is None:
        raise DeformKitError("this build of the native module has no deformkit.%s (%s)"
                             % (m.native_class, m.label))
    return dk, cls

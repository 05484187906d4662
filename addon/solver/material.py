"""Linear reconstruction's material map: from the Material group's paint to per-edge values,
and its display as a colour attribute."""

import numpy as np

from .. import methods
from . import calls


# Softness 1 multiplies the painted edges' weights by this (the material map of
# docs/methods/fundamental.md): E_x's by MATERIAL_SOFTEST, E_f's by its inverse.
MATERIAL_SOFTEST = 20.0


def material_map(dk, dkmesh, paint, kw, opts):
    """The per-edge material of linear reconstruction from the Material group's paint
    (vertex indices, weights in (0, 1]): each painted vertex's value is
    MATERIAL_SOFTEST ** (softness * weight). Interpolate: a harmonic map through the painted
    vertices, the handles and fixed vertices held at 1 (as built); Smooth: the raw values
    (1 where unpainted) averaged `smooth_iterations` times over the edges. The direction
    (soft = a higher stretching and a lower bending weight) is the one measured to
    concentrate a fold at the paint (docs/methods/fundamental.md, "Measured")."""
    idx, w = paint
    n = dkmesh.n_vertices
    val = MATERIAL_SOFTEST ** (float(opts.softness) * np.asarray(w, dtype=np.float64))
    edges = np.asarray(dkmesh.edges)
    if opts.material_mode == "interpolate":
        held = [np.asarray(h) for h in kw["handles"]]
        if kw.get("fixed") is not None:
            held.append(np.asarray(kw["fixed"]))
        held = np.setdiff1d(np.concatenate(held) if held else np.zeros(0, np.int64), idx)
        painted = np.concatenate([np.asarray(idx, dtype=np.int64), held.astype(np.int64)])
        values = np.concatenate([val, np.ones(len(held))])
        return np.asarray(calls._native_call("material", dk.harmonic_material, dkmesh, painted,
                                             values))
    u = np.ones(n)
    u[idx] = val
    for _ in range(int(opts.smooth_iterations)):  # Jacobi averaging over the neighbours
        acc = np.zeros(n)
        deg = np.zeros(n)
        np.add.at(acc, edges[:, 0], u[edges[:, 1]])
        np.add.at(acc, edges[:, 1], u[edges[:, 0]])
        np.add.at(deg, edges[:, 0], 1.0)
        np.add.at(deg, edges[:, 1], 1.0)
        u = np.where(deg > 0, 0.5 * u + 0.5 * acc / np.maximum(deg, 1.0), u)
    return 0.5 * (u[edges[:, 0]] + u[edges[:, 1]])


def show_material(obj, d, e):
    """Show Material (methods with a 'material' map): the map as the colour attribute
    "dk_<uid>_material" (grey where as built, yellow where softest; the viewport shows it
    in Solid mode with Attribute colouring), made the active colour; removed when off or
    when nothing is painted. Writes only on a change."""
    m = methods.get(d.method)
    if "material" not in m.maps:
        return
    want = bool(getattr(d.options, "show_material", False)) and e.material is not None
    key = (want, id(e.material))
    if e.material_shown == key:
        return
    me = obj.data
    name = "dk_%s_material" % d.uid
    old = me.color_attributes.get(name) if hasattr(me, "color_attributes") else None
    if not want:
        if old is not None:
            me.color_attributes.remove(old)
        e.material_shown = key
        return
    edges = np.asarray(e.dkmesh.edges)
    acc = np.zeros(e.n_vertices)
    deg = np.zeros(e.n_vertices)
    np.add.at(acc, edges.ravel(), np.repeat(e.material, 2))
    np.add.at(deg, edges.ravel(), 1.0)
    u = np.where(deg > 0, acc / np.maximum(deg, 1.0), 1.0)
    t = np.clip(np.log(np.maximum(u, 1e-12)) / np.log(MATERIAL_SOFTEST), 0.0, 1.0)[:, None]
    rgba = (1.0 - t) * np.array([0.5, 0.5, 0.5, 1.0]) + t * np.array([1.0, 0.85, 0.1, 1.0])
    if old is None or old.domain != "POINT" or old.data_type != "FLOAT_COLOR":
        if old is not None:
            me.color_attributes.remove(old)
        old = me.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    old.data.foreach_set("color", np.ascontiguousarray(rgba, dtype=np.float32).ravel())
    me.color_attributes.active_color = old
    e.material_shown = key

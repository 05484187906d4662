"""The collector for controls that are vertex groups of the deformed mesh: handles, the
region, the fixed part, a material or stiffness paint, a cut; validated into index arrays."""

import numpy as np

from .. import methods
from ..errors import DeformKitError, OverlapError
from ..handles import target_world
from ..text import plural
from . import blender_data

uses_handles = True


def capture(obj, d, depsgraph=None):
    """Nothing: the handles' placement at Bind is kept by binding.bind_end (bind_matrix)."""
    return None


def store(d, captured):
    """Nothing to keep (capture)."""


def settings_key(d):
    m = methods.get(d.method)
    return (methods.signature(m, d.options), d.roi_group, d.fixed_group, d.material_group,
            tuple((h.vertex_group, h.use_weights) for h in d.handles),
            methods.poses_reader(m).signature(d.id_data, d.options) if m.poses is not None
            else None)


def group_names(obj, d):
    """The names of the vertex groups `d` reads (handles, region, fixed, material, cut)."""
    m = methods.get(d.method)
    names = {h.vertex_group for h in d.handles if h.vertex_group}
    names.update(g for g in (d.roi_group, d.fixed_group, d.material_group) if g)
    if "cut" in m.maps:
        names.update(g for g in (getattr(d.options, o) for o in m.cut_options) if g)
    names.update(g for g in (getattr(d.options, o) for o in m.group_maps) if g)
    return names


def exist(obj, d):
    """Whether every vertex group `d` reads is still there: a name lookup each, cheap enough
    for every solve. A group removed by a script (obj.vertex_groups.remove) tags no update,
    so the binding's copy of it went on being used, and Apply wrote its result (the second
    hostile review); the next solve now re-reads the groups, and collect names the missing
    one."""
    vgs = obj.vertex_groups
    return all(vgs.get(n) is not None for n in group_names(obj, d))


def collect(obj, d, captured=None):
    """Validated constraint arrays from the deformer's vertex groups (raises DeformKitError);
    `captured` is capture()'s None."""
    blender_data.check_object(obj, d)
    m = methods.get(d.method)
    # a simulation or a blend of poses needs none (a blend: unless it has no poses)
    if len(d.handles) == 0 and m.needs_handles:
        raise DeformKitError("no handles: add one (Add Handle from Selection in Edit Mode)")
    names = set()
    for h in d.handles:
        if not h.vertex_group:
            raise DeformKitError("handle '%s' has no vertex group" % h.name)
        if obj.vertex_groups.get(h.vertex_group) is None:
            raise DeformKitError("handle '%s': vertex group '%s' does not exist"
                                 % (h.name, h.vertex_group))
        names.add(h.vertex_group)
        target_world(h)  # raises for a missing/deleted target or bone
    for label, g in (("region", d.roi_group), ("fixed", d.fixed_group),
                     (m.material_label.lower(), d.material_group)):
        if g:
            if obj.vertex_groups.get(g) is None:
                raise DeformKitError("%s vertex group '%s' does not exist" % (label, g))
            names.add(g)
    cut = [getattr(d.options, o) for o in m.cut_options] if "cut" in m.maps else []
    if any(cut):
        labels = [next(o.label for o in m.options if o.name == n) for n in m.cut_options]
        for label, g in zip(labels, cut):
            if not g:
                raise DeformKitError("%s is set but %s is not: a cut needs both vertex groups"
                                     % (labels[1 - labels.index(label)], label))
            if obj.vertex_groups.get(g) is None:
                raise DeformKitError("%s: vertex group '%s' does not exist" % (label, g))
        if cut[0] == cut[1]:
            raise DeformKitError("%s and %s are the same vertex group '%s'"
                                 % (labels[0], labels[1], cut[0]))
        names.update(cut)
    for o in m.group_maps:   # painted factors
        g = getattr(d.options, o)
        if g:
            if obj.vertex_groups.get(g) is None:
                label = next(x.label for x in m.options if x.name == o)
                raise DeformKitError("%s: vertex group '%s' does not exist" % (label, g))
            names.add(g)
    groups = blender_data.read_groups(obj, names)
    handles, weights = [], []
    seen = {}
    for h in d.handles:
        idx, w = groups[h.vertex_group]
        if len(idx) == 0:
            raise DeformKitError("handle '%s': vertex group '%s' is empty"
                                 % (h.name, h.vertex_group))
        if h.vertex_group in seen:
            raise DeformKitError("handles '%s' and '%s' use the same vertex group '%s'"
                                 % (seen[h.vertex_group], h.name, h.vertex_group))
        seen[h.vertex_group] = h.name
        handles.append(idx)
        weights.append(w if h.use_weights else np.ones(len(idx)))
    if len(handles) > 1:
        allh = np.concatenate(handles)
        u, c = np.unique(allh, return_counts=True)
        if (c > 1).any():
            v = int(u[c > 1][0])
            owners = [h for h, idx in zip(d.handles, handles) if v in idx]
            raise OverlapError("handles '%s' and '%s' share %s: a vertex can follow one "
                               "handle only" % (owners[0].name, owners[1].name,
                                                plural(int((c > 1).sum()), "vertex")),
                               owners[0].vertex_group, owners[1].vertex_group)
    fixed = roi = None
    if d.fixed_group:
        fixed = groups[d.fixed_group][0]
        if len(fixed) == 0:
            raise DeformKitError("fixed vertex group '%s' is empty" % d.fixed_group)
        for h, idx in zip(d.handles, handles):
            both = np.intersect1d(idx, fixed)
            if len(both):
                raise OverlapError("handle '%s' overlaps the fixed group '%s' in %s: remove "
                                   "them from one group"
                                   % (h.name, d.fixed_group, plural(len(both), "vertex")),
                                   h.vertex_group, d.fixed_group)
    if d.roi_group:
        roi = groups[d.roi_group][0]
        if len(roi) == 0:
            raise DeformKitError("region vertex group '%s' is empty" % d.roi_group)
    if m.region_is_handle and roi is not None:
        # the Region group is the region that moves (eigen deformation's R), with the
        # first handle's motion
        if len(d.handles) > 1:
            raise DeformKitError("%s moves the Region group with one handle: remove the "
                                 "other handles or clear the Region group" % m.label)
        both = np.intersect1d(roi, fixed) if fixed is not None else ()
        if len(both):
            raise OverlapError("the Region group '%s' overlaps the fixed group '%s' in %d "
                               "vertices: remove them from one group"
                               % (d.roi_group, d.fixed_group, len(both)),
                               d.roi_group, d.fixed_group)
        handles, roi = [roi], None
        kw = dict(m.region_kw)
    else:
        kw = {}
    kw.update(handles=handles, fixed=fixed, roi=roi)
    if m.poses is not None:  # the example poses (shape keys): their shapes are part of the key
        P = methods.poses_reader(m).poses(obj, d.options, blender_data.rest_positions(obj.data))
        if P is None and not handles:
            raise DeformKitError("no shape keys to blend: add shape keys to the mesh (Object "
                                 "Data properties, Shape Keys)")
        if P is not None:
            kw["poses"] = P
    if "stiffness" in m.maps and d.material_group:
        idx, w = groups[d.material_group]
        s = np.ones(len(obj.data.vertices))
        s[idx] = 1.0 + (getattr(d.options, m.stiffness_option) - 1.0) * w
        kw["stiffness"] = s
    if "paint" in m.maps and d.material_group:
        idx, w = groups[d.material_group]
        p = np.zeros(len(obj.data.vertices))
        p[idx] = w
        kw[m.paint_keyword] = p
    for o, keyword in m.group_maps.items():
        g = getattr(d.options, o)
        if g:
            idx, w = groups[g]
            p = np.ones(len(obj.data.vertices))
            p[idx] = w
            kw[keyword] = p
    if "material" in m.maps and d.material_group:
        idx, w = groups[d.material_group]
        kw["material_paint"] = (idx, w)
    if "handle_weights" in m.maps and any(h.use_weights for h in d.handles):
        kw["handle_weights"] = weights
    if any(cut):
        kw["cut"] = tuple(groups[g][0] for g in cut)
        for label, g, idx in zip(labels, cut, kw["cut"]):
            if len(idx) == 0:
                raise DeformKitError("%s: vertex group '%s' is empty" % (label, g))
    key = b"".join(np.ascontiguousarray(a).tobytes() for a in handles) + b"|" + b"|".join(
        b"" if x is None else np.ascontiguousarray(x).tobytes()
        for x in (fixed, roi, kw.get("stiffness"), kw.get(m.paint_keyword or "")) +
        tuple(kw.get(k) for k in m.group_maps.values()) + kw.get("cut", ())
        + kw.get("material_paint", ()))
    key += b"|" + b"".join(w.tobytes() for w in kw.get("handle_weights", []))
    key += b"|" + (kw["poses"].tobytes() if "poses" in kw else b"")
    key += b"|" + repr(sorted((k, x) for k, x in kw.items() if isinstance(x, str))).encode()
    return kw, key

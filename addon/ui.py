"""UI: a panel in the Properties editor's Modifiers tab, menus in the Modifiers tab and the 3D
view. Drawing only reads settings and the solver's runtime figures; it never solves."""

import bpy

from . import animated_input, bake, geonodes, methods, native, solver


class DEFORMKIT_UL_deformers(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_prop, index=0):
        m = methods.BY_ID.get(item.method)
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False, icon=m.icon if m else "QUESTION")
        mod = geonodes.find_modifier(context.object, item) if context.object else None
        if item.status_is_error:
            row.label(text="", icon="ERROR")
        elif item.bound:
            row.label(text="", icon="LINKED")
        else:
            row.label(text="", icon="UNLINKED")
        if mod is not None:
            row.prop(mod, "show_viewport", text="", emboss=False)
            row.prop(mod, "show_render", text="", emboss=False)


class DEFORMKIT_UL_handles(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_prop, index=0):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False, icon="HOOK")
        obj = context.object
        bad = (not item.vertex_group or item.target is None
               or (obj is not None and obj.vertex_groups.get(item.vertex_group) is None))
        tgt = item.target.name if item.target else "no target"
        if item.subtarget:
            tgt += ":" + item.subtarget
        row.label(text=tgt, icon="ERROR" if bad else "OBJECT_DATA")


def draw_options(layout, d, obj=None):
    """The method's options: the everyday ones, then the expert ones (Option.advanced) under
    an "Advanced" row with a disclosure triangle, collapsed unless the deformer's
    show_advanced is on (a stored toggle, not layout.panel(): that needs Blender 4.1)."""
    m = methods.get(d.method)
    opts = d.options
    if m.draw is not None:
        m.draw(layout, opts)
        return
    shown = [o for o in m.options if not (o.shown_with and not getattr(d, o.shown_with))
             and not (o.shown_if and getattr(opts, o.shown_if[0]) not in o.shown_if[1])]
    col = layout.column()
    for o in shown:
        if not o.advanced:
            _draw_option(col, opts, o, obj)
    advanced = [o for o in shown if o.advanced]
    if not advanced:
        return
    row = layout.row()
    row.use_property_split = False
    row.alignment = "LEFT"
    row.prop(d, "show_advanced", emboss=False,
             icon="TRIA_DOWN" if d.show_advanced else "TRIA_RIGHT")
    if d.show_advanced:
        sub = layout.column()
        for o in advanced:
            _draw_option(sub, opts, o, obj)


def _draw_option(layout, opts, o, obj):
    if o.type == "GROUP" and obj is not None:
        layout.prop_search(opts, o.name, obj, "vertex_groups")
    else:
        layout.prop(opts, o.name)


class DEFORMKIT_PT_modifiers(bpy.types.Panel):
    bl_label = "DeformKit"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "modifier"

    @classmethod
    def poll(cls, context):
        # only meshes that have a deformer: the others get the Add DeformKit Deformer menu
        # at the top of the Modifiers tab, not a whole panel
        obj = context.object
        return obj is not None and obj.type == "MESH" and len(obj.deformkit.deformers) > 0

    def draw(self, context):
        layout = self.layout
        obj = context.object
        width = wrap_width(context)
        if native.load() is None:
            draw_wrapped(layout.box(), native.error, "ERROR", width, alert=True)
        dks = obj.deformkit
        row = layout.row()
        row.template_list("DEFORMKIT_UL_deformers", "", dks, "deformers", dks, "active_index",
                          rows=2)
        col = row.column(align=True)
        col.menu("DEFORMKIT_MT_add", icon="ADD", text="")
        col.operator("deformkit.remove_deformer", icon="REMOVE", text="")
        col.separator()
        col.operator("deformkit.move_deformer", icon="TRIA_UP", text="").direction = "UP"
        col.operator("deformkit.move_deformer", icon="TRIA_DOWN", text="").direction = "DOWN"
        if not 0 <= dks.active_index < len(dks.deformers):
            layout.label(text="Add a deformer, or select vertices in Edit Mode and use "
                              "Add Handle from Selection", icon="INFO")
            return
        d = dks.deformers[dks.active_index]
        m = methods.get(d.method)
        mod = geonodes.find_modifier(obj, d)

        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = True
        col.prop(d, "method")
        if mod is not None:
            col.prop(*geonodes.factor_prop(mod), text="Factor")
        else:
            r = col.row()
            r.alert = True
            r.label(text="its Geometry Nodes modifier was removed", icon="ERROR")
            col.operator("deformkit.restore_modifier", icon="MODIFIER")
        if not solver.controls.uses_handles(d):
            draw_control(layout, col, obj, d)
        else:
            draw_handles(layout, col, obj, d, m)

        box = layout.box()
        box.label(text="%s Options" % m.label, icon=m.icon)
        box.use_property_split = True
        draw_options(box, d, obj)

        row = layout.row(align=True)
        if d.bound:
            row.operator("deformkit.bind", text="Rebind", icon="FILE_REFRESH")
            row.operator("deformkit.unbind", text="Unbind", icon="UNLINKED")
        else:
            row.operator("deformkit.bind", text="Bind", icon="LINKED")
        draw_rest_frame(layout, d)
        draw_wrapped(layout, solver.status_text(d), "ERROR" if d.status_is_error else "INFO",
                     width, alert=d.status_is_error)
        draw_rebinding(layout, obj, d)
        draw_overlap(layout, d)
        hidden = bake.hidden_reason(obj, d) if mod is not None and d.bound else None
        if hidden:
            draw_wrapped(layout, "%s: nothing shows the result" % hidden, "HIDE_ON", width,
                         alert=True)
        for w in solver.bind_warnings(obj, d) if d.bound else ():
            draw_wrapped(layout, w, "ERROR", width)
        why = bake.animated_reason(obj, d) if d.bound and bake.state(obj, d) is None else None
        if why:
            draw_wrapped(layout.box(), "Animated (%s) and not baked: without DeformKit, this "
                         "file shows one frozen pose on every frame. Bake before rendering "
                         "elsewhere." % why, "ERROR", width)
        summary = solver.solve_summary(obj, d)
        if summary:
            layout.label(text=summary, icon="TIME")
        sim = solver.simulation_text(obj, d)
        if sim:
            draw_wrapped(layout, sim, "PHYSICS", width)
        fit = solver.fit_warning(obj, d) if d.bound else None
        if fit:
            draw_wrapped(layout, fit, "INFO", width)
        note = animated_input.pose_note(obj, d) if d.bound else None
        if note:
            draw_wrapped(layout, note, "INFO", width)
        if solver.previewing(obj, d):
            layout.label(text="preview: the full result follows when the handles stop",
                         icon="SORTTIME")
        elif d.bound and solver.refining(obj, d):
            layout.label(text="refining\u2026", icon="SORTTIME")
        row = layout.row(align=True)
        row.operator("deformkit.apply", text="Apply").mode = "MESH"
        row.operator("deformkit.apply", text="Apply as Shape Key").mode = "SHAPE_KEY"
        # a corrective key holds a still edit: not a simulation's frame
        if d.bound and not solver.simulation.is_dynamic(methods.get(d.method)) and any(
                m.type == "ARMATURE" for m in animated_input.modifiers_above(obj, d)):
            layout.operator("deformkit.bake_corrective", icon="SHAPEKEY_DATA")
        draw_bake(layout, obj, d, width)


def draw_handles(layout, col, obj, d, m):
    """The groups and handles of a method driven by vertex groups moved by targets."""
    col.prop_search(d, "roi_group", obj, "vertex_groups", text="Region")
    col.prop_search(d, "fixed_group", obj, "vertex_groups", text="Fixed")
    if {"stiffness", "material", "paint"} & set(m.maps):
        col.prop_search(d, "material_group", obj, "vertex_groups", text=m.material_label)

    layout.label(text="Handles")
    row = layout.row()
    row.template_list("DEFORMKIT_UL_handles", "", d, "handles", d, "active_handle", rows=2)
    c = row.column(align=True)
    c.operator("deformkit.add_handle_from_selection", icon="ADD", text="")
    c.operator("deformkit.add_handle", icon="PLUS", text="")
    c.operator("deformkit.remove_handle", icon="REMOVE", text="")
    if 0 <= d.active_handle < len(d.handles):
        h = d.handles[d.active_handle]
        hc = layout.column()
        hc.use_property_split = True
        hc.use_property_decorate = False
        hc.prop_search(h, "vertex_group", obj, "vertex_groups")
        hc.prop(h, "target")
        if h.target is not None and h.target.type == "ARMATURE":
            hc.prop_search(h, "subtarget", h.target.data, "bones")
        if "handle_weights" in m.maps:
            hc.prop(h, "use_weights")
        if animated_input.input_movers(obj, d) is not None:  # what the edit does there
            hc.prop(h, "follow")
    # a simulation always moves towards its input (its goal shape), a blend of poses edits
    # it: no Solve From
    if animated_input.input_movers(obj, d) is not None and m.needs_handles:
        layout.prop(d, "solve_from")
    if obj.mode == "EDIT":
        layout.operator("deformkit.add_handle_from_selection", icon="HOOK")


def draw_control(layout, col, obj, d):
    """The control object of a method driven by one (a lattice, a cage), and the operator
    that makes one around the mesh."""
    c = solver.controls.of(d)
    row = col.row(align=True)
    row.prop(d, "control_object", text=c.LABEL)
    if c.MAKE_OPERATOR:
        layout.operator(c.MAKE_OPERATOR, icon="ADD")


def draw_rebinding(layout, obj, d):
    """The re-bind that runs after an option or method change (solver.rebinding)."""
    t = solver.rebind_text(obj, d)
    if t is not None:
        layout.label(text=t, icon="SORTTIME")


def draw_overlap(layout, d):
    """The ways out of an overlap error: select the shared vertices, or remove them from
    either group."""
    if not d.status_overlap or not d.status_is_error:
        return
    a, b = d.status_overlap.split("\t")
    row = layout.row(align=True)
    op = row.operator("deformkit.overlap", text="Select Shared", icon="RESTRICT_SELECT_OFF")
    op.action, op.group, op.other = "SELECT", a, b
    for g, other in ((a, b), (b, a)):
        op = row.operator("deformkit.overlap", text="Remove from '%s'" % g, icon="REMOVE")
        op.action, op.group, op.other = "REMOVE", g, other


def draw_bake(layout, obj, d, width=60):
    """The bake buttons, or the bake that shows in place of the live result with the ways
    out (Free Bake, Re-bake)."""
    st = bake.state(obj, d)
    if st is not None:
        box = layout.box()
        draw_wrapped(box, st["text"], "FILE_CACHE" if st["kind"] == "PC2" else "SHAPEKEY_DATA",
                     width, alert=True)
        row = box.row(align=True)
        row.operator("deformkit.free_bake", icon="TRASH")
        if not st["broken"]:
            row.operator("deformkit.rebake", icon="FILE_REFRESH")
        return
    row = layout.row(align=True)
    row.operator("deformkit.bake", text="Bake to Point Cache", icon="FILE_CACHE").mode = "PC2"
    row.operator("deformkit.bake", text="Bake to Shape Keys").mode = "SHAPE_KEYS"
    layout.prop(d, "bake_file", text="Cache File")


def wrap_width(context):
    """How many characters of label text fit one line of the region being drawn: its width
    less the icon and the panel's margins, at about 6.5 px a character at UI scale 1 (Blender's
    default font); 60 when there is no region (scripts, tests)."""
    region = getattr(context, "region", None)
    width = getattr(region, "width", 0) or 0
    if width <= 0:
        return 60
    prefs = bpy.context.preferences  # system.ui_scale has the display's DPI (0 without one)
    scale = prefs.system.ui_scale or prefs.view.ui_scale or 1.0
    return max(20, int((width - 60 * scale) / (6.5 * scale)))


def draw_wrapped(layout, text, icon, width, alert=False):
    """`text` over as many label lines as it needs at `width` characters, the icon on the
    first (long errors were cut off at the panel's edge)."""
    col = layout.column(align=True)
    col.alert = alert
    for i, line in enumerate(_wrap(text, width)):
        col.label(text=line, icon=icon if i == 0 else "BLANK1")


def _wrap(text, width):
    words, lines, cur = text.split(), [], ""
    for w in words:
        if len(cur) + len(w) + 1 > width and cur:
            lines.append(cur)
            cur = w
        else:
            cur = (cur + " " + w).strip()
    if cur:
        lines.append(cur)
    return lines or [""]


def driven_by(target):
    """(mesh object, deformer index, deformer, handle) of every handle that `target` moves,
    and (mesh object, deformer index, deformer, None) of every deformer it is the control
    object (lattice, cage) of."""
    out = []
    for obj in bpy.data.objects:
        if obj.type != "MESH":
            continue
        for i, d in enumerate(obj.deformkit.deformers):
            if d.control_object == target and not solver.controls.uses_handles(d):
                out.append((obj, i, d, None))
                continue
            for h in d.handles:
                if h.target == target:
                    out.append((obj, i, d, h))
    return out


def draw_deformer_summary(layout, obj, i, d, handle=None, width=40):
    """One deformer in brief: its name (and the handle), status, Bind / Rebind, its bake."""
    box = layout.box()
    m = methods.BY_ID.get(d.method)
    title = "%s: %s" % (obj.name, d.name) if handle is None else \
        "%s: %s, handle '%s'" % (obj.name, d.name, handle.name)
    # wrapped like the status: the sidebar is narrow, and "Grid: Defor... handle 'tip'" said
    # neither which deformer nor which handle
    draw_wrapped(box, title, m.icon if m else "QUESTION", width)
    draw_wrapped(box, solver.status_text(d), "ERROR" if d.status_is_error else "INFO", width,
                 alert=d.status_is_error)
    draw_rebinding(box, obj, d)
    st = bake.state(obj, d)
    if st is not None:
        r = box.row()
        r.alert = True
        r.label(text="baked: edits don't show", icon="FILE_CACHE")
    row = box.row(align=True)
    op = row.operator("deformkit.bind", text="Rebind" if d.bound else "Bind",
                      icon="FILE_REFRESH" if d.bound else "LINKED")
    op.object_name, op.deformer_index = obj.name, i
    if st is not None:
        op = row.operator("deformkit.free_bake", icon="TRASH")
        op.object_name, op.deformer_index = obj.name, i
    elif d.bound:  # an animator's next step: play what was keyed without DeformKit
        op = row.operator("deformkit.bake", text="Bake", icon="FILE_CACHE")
        op.object_name, op.deformer_index, op.mode = obj.name, i, "PC2"
    draw_rest_frame(box, d)


def draw_rest_frame(layout, d):
    """Where Bind takes the rest from, next to the Bind button (solver.rest_frame)."""
    r = layout.row(align=True)
    r.prop(d, "rest_frame_from", text="Rest")
    if d.rest_frame_from == "FRAME":
        r.prop(d, "rest_frame", text="")


class DEFORMKIT_PT_sidebar(bpy.types.Panel):
    """The 3D View's sidebar (N) tab: the deformers of the active mesh, or those that the
    active object (a handle's empty or armature) drives, with their status and Bind, so that
    selecting the handle to move it does not take them out of view."""
    bl_label = "DeformKit"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "DeformKit"

    @classmethod
    def poll(cls, context):
        return True

    def draw(self, context):
        layout = self.layout
        obj = context.object
        width = wrap_width(context)
        if obj is not None and obj.type == "MESH" and len(obj.deformkit.deformers):
            for i, d in enumerate(obj.deformkit.deformers):
                draw_deformer_summary(layout, obj, i, d, width=width)
            return
        drives = driven_by(obj) if obj is not None else []
        if drives:
            layout.label(text="%s moves:" % obj.name, icon="HOOK")
            for mesh, i, d, h in drives:
                draw_deformer_summary(layout, mesh, i, d, h, width=width)
            return
        draw_wrapped(layout, "Select a mesh with a DeformKit deformer, or a handle's target. "
                     "Add a deformer from the Modifiers tab or the Object menu.", "INFO", width)


class DEFORMKIT_PT_handle_target(bpy.types.Panel):
    """A line on a handle target's Object tab saying what it drives."""
    bl_label = "DeformKit Handle"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and bool(driven_by(context.object))

    def draw(self, context):
        width = wrap_width(context)
        for mesh, i, d, h in driven_by(context.object):
            text = ("moves handle '%s' of %s (%s)" % (h.name, mesh.name, d.name)
                    if h is not None else "moves %s (%s)" % (mesh.name, d.name))
            draw_wrapped(self.layout, text, "HOOK", width)


class DEFORMKIT_MT_add(bpy.types.Menu):
    bl_label = "Add DeformKit Deformer"
    bl_idname = "DEFORMKIT_MT_add"

    def draw(self, context):
        for m in methods.METHODS:
            self.layout.operator("deformkit.add_deformer", text=m.label, icon=m.icon).method = m.id


def _draw_modifier_tab(self, context):
    if context.object is not None and context.object.type == "MESH":
        self.layout.menu("DEFORMKIT_MT_add", icon="MOD_MESHDEFORM", text="Add DeformKit Deformer")


def _draw_object_menu(self, context):
    if context.object is None or context.object.type != "MESH":
        return  # DeformKit deforms meshes: no entry for empties, cameras, armatures...
    self.layout.separator()
    self.layout.menu("DEFORMKIT_MT_add", icon="MOD_MESHDEFORM")


def _draw_modifier_add_deform(self, context):
    """The Add Modifier menu's Deform section (Blender 4.0+), where artists look for
    deformers: every DeformKit method under a DeformKit heading, after Blender's own."""
    if context.object is None or context.object.type != "MESH":
        return
    self.layout.separator()
    self.layout.label(text="DeformKit")
    for m in methods.METHODS:
        self.layout.operator("deformkit.add_deformer", text=m.label, icon=m.icon).method = m.id


def _draw_edit_menu(self, context):
    self.layout.separator()
    self.layout.operator("deformkit.add_handle_from_selection", icon="HOOK")


CLASSES = [DEFORMKIT_UL_deformers, DEFORMKIT_UL_handles, DEFORMKIT_PT_modifiers, DEFORMKIT_MT_add,
           DEFORMKIT_PT_sidebar, DEFORMKIT_PT_handle_target]

# (menu or panel, draw function appended to it, whether every supported Blender has it)
_APPENDS = [
    ("DATA_PT_modifiers", _draw_modifier_tab, True),
    ("VIEW3D_MT_object", _draw_object_menu, True),
    ("VIEW3D_MT_edit_mesh_vertices", _draw_edit_menu, True),
    ("VIEW3D_MT_edit_mesh_context_menu", _draw_edit_menu, True),
    # the Add Modifier menu's Deform section: 4.0+ (3.4-3.6 list modifiers from an enum)
    ("OBJECT_MT_modifier_add_deform", _draw_modifier_add_deform, False),
]


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    for name, fn, _everywhere in _APPENDS:
        t = getattr(bpy.types, name, None)
        if t is not None:
            t.append(fn)


def unregister():
    for name, fn, _everywhere in _APPENDS:
        t = getattr(bpy.types, name, None)
        if t is not None:
            t.remove(fn)
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)

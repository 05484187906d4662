"""UI: a panel in the Properties editor's Modifiers tab, menus in the Modifiers tab and the 3D
view. Drawing only reads settings and the solver's runtime figures; it never solves."""

import bpy

from . import geonodes, methods, native, solver


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
    shown = [o for o in m.options if not (o.shown_with and not getattr(d, o.shown_with))]
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
        return context.object is not None and context.object.type == "MESH"

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
            col.prop(mod, geonodes.factor_path(mod), text="Factor")
        else:
            r = col.row()
            r.alert = True
            r.label(text="its Geometry Nodes modifier was removed: re-add the deformer",
                    icon="ERROR")
        col.prop_search(d, "roi_group", obj, "vertex_groups", text="Region")
        col.prop_search(d, "fixed_group", obj, "vertex_groups", text="Fixed")
        if "stiffness" in m.maps or "material" in m.maps:
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
        if obj.mode == "EDIT":
            layout.operator("deformkit.add_handle_from_selection", icon="HOOK")

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
        draw_wrapped(layout, solver.status_text(d), "ERROR" if d.status_is_error else "INFO",
                     width, alert=d.status_is_error)
        summary = solver.solve_summary(obj, d)
        if summary:
            layout.label(text=summary, icon="TIME")
        row = layout.row(align=True)
        row.operator("deformkit.apply", text="Apply").mode = "MESH"
        row.operator("deformkit.apply", text="Apply as Shape Key").mode = "SHAPE_KEY"
        row = layout.row(align=True)
        row.operator("deformkit.bake", text="Bake to Point Cache", icon="FILE_CACHE").mode = "PC2"
        row.operator("deformkit.bake", text="Bake to Shape Keys").mode = "SHAPE_KEYS"


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
    self.layout.separator()
    self.layout.menu("DEFORMKIT_MT_add", icon="MOD_MESHDEFORM")


def _draw_edit_menu(self, context):
    self.layout.separator()
    self.layout.operator("deformkit.add_handle_from_selection", icon="HOOK")


CLASSES = [DEFORMKIT_UL_deformers, DEFORMKIT_UL_handles, DEFORMKIT_PT_modifiers, DEFORMKIT_MT_add]

_APPENDS = [
    ("DATA_PT_modifiers", _draw_modifier_tab),
    ("VIEW3D_MT_object", _draw_object_menu),
    ("VIEW3D_MT_edit_mesh_vertices", _draw_edit_menu),
    ("VIEW3D_MT_edit_mesh_context_menu", _draw_edit_menu),
]


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    for name, fn in _APPENDS:
        t = getattr(bpy.types, name, None)
        if t is not None:
            t.append(fn)


def unregister():
    for name, fn in _APPENDS:
        t = getattr(bpy.types, name, None)
        if t is not None:
            t.remove(fn)
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)

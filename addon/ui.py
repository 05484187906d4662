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
    m = methods.get(d.method)
    opts = d.options
    if m.draw is not None:
        m.draw(layout, opts)
        return
    col = layout.column()
    for o in m.options:
        if o.shown_with and not getattr(d, o.shown_with):
            continue
        if o.type == "GROUP" and obj is not None:
            col.prop_search(opts, o.name, obj, "vertex_groups")
        else:
            col.prop(opts, o.name)


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
        if native.load() is None:
            box = layout.box()
            box.alert = True
            for i, line in enumerate(_wrap(native.error, 60)):
                box.label(text=line, icon="ERROR" if i == 0 else "BLANK1")
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
            col.prop_search(d, "material_group", obj, "vertex_groups", text="Material")

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
        r = layout.row()
        if d.status:
            r.alert = d.status_is_error
            r.label(text=d.status, icon="ERROR" if d.status_is_error else "INFO")
        rt = solver.runtime.get((obj.name, d.uid))
        if rt and d.bound and not d.status_is_error:
            layout.label(text="last solve %.1f ms, %d iterations%s" % (
                rt["ms"], rt["iterations"], "" if rt["converged"] else " (not converged)"),
                icon="TIME")
        if d.bound and solver.refining(obj, d):
            layout.label(text="refining\u2026", icon="SORTTIME")
        row = layout.row(align=True)
        row.operator("deformkit.apply", text="Apply").mode = "MESH"
        row.operator("deformkit.apply", text="Apply as Shape Key").mode = "SHAPE_KEY"
        row = layout.row(align=True)
        row.operator("deformkit.bake", text="Bake to Point Cache", icon="FILE_CACHE").mode = "PC2"
        row.operator("deformkit.bake", text="Bake to Shape Keys").mode = "SHAPE_KEYS"


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

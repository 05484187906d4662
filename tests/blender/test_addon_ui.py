"""The add-on's UI code against this Blender's API, without a window: every panel, list and
menu of the add-on is drawn into a recording layout, in each state a deformer can be in
(none, unbound, bound, error, a handle on an armature, options of every method), and every
call is checked against this Blender's RNA: each property path exists on its data (or is an
ID property that exists), each prop_search collection exists, each operator exists and each
keyword set on it is one of its properties, each menu is registered, and each icon is one this
Blender knows (icons are renamed between releases). The screenshot test shows the real panel
under Xvfb in Debian's Blender; this one reaches the Blenders that run only as a module."""
import os
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402

R = S.Results("test_addon_ui")
ICONS = set(bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items.keys())
PROBLEMS = []


def problem(text):
    if text not in PROBLEMS:
        PROBLEMS.append(text)


def check_icon(icon, where):
    if icon is not None and icon not in ICONS:
        problem("%s: icon %r unknown to Blender %s" % (where, icon, bpy.app.version_string))


class OperatorProps:
    """What layout.operator() returns: setting an attribute checks the operator has it."""

    def __init__(self, idname, rna):
        object.__setattr__(self, "_idname", idname)
        object.__setattr__(self, "_props", set(rna.properties.keys()) if rna else set())

    def __setattr__(self, name, value):
        if name not in self._props:
            problem("operator %s has no property %r" % (self._idname, name))


class Layout:
    """Records nothing but checks everything a draw function asks of a UILayout."""

    def __init__(self, calls):
        object.__setattr__(self, "calls", calls)

    def __setattr__(self, name, value):   # alert, enabled, use_property_split, ...
        if name not in bpy.types.UILayout.bl_rna.properties:
            problem("UILayout has no attribute %r" % name)

    def _sub(self, *a, **kw):
        self.calls.append("container")
        return Layout(self.calls)

    row = column = box = split = column_flow = grid_flow = _sub

    def separator(self, *a, **kw):
        self.calls.append("separator")

    def label(self, text="", icon=None, **kw):
        check_icon(icon, "label %r" % text)
        self.calls.append("label " + str(text))

    def prop(self, data, path, text=None, icon=None, **kw):
        check_icon(icon, "prop %s" % path)
        if path.startswith('["') and path.endswith('"]'):
            try:
                data[path[2:-2]]
            except KeyError:
                problem("%s has no ID property %s" % (data, path))
        elif path not in data.bl_rna.properties:
            problem("%s has no property %r" % (type(data).__name__, path))
        self.calls.append("prop " + path)

    def prop_search(self, data, prop, search_data, search_prop, text=None, icon=None, **kw):
        check_icon(icon, "prop_search %s" % prop)
        if prop not in data.bl_rna.properties:
            problem("%s has no property %r" % (type(data).__name__, prop))
        if search_prop not in search_data.bl_rna.properties:
            problem("%s has no collection %r" % (type(search_data).__name__, search_prop))
        self.calls.append("prop_search " + prop)

    def operator(self, idname, text=None, icon=None, **kw):
        check_icon(icon, "operator %s" % idname)
        mod, name = idname.split(".")
        try:
            rna = getattr(getattr(bpy.ops, mod), name).get_rna_type()
        except (AttributeError, KeyError):
            problem("no operator %s" % idname)
            rna = None
        self.calls.append("operator " + idname)
        return OperatorProps(idname, rna)

    def menu(self, idname, text=None, icon=None, **kw):
        check_icon(icon, "menu %s" % idname)
        if not hasattr(bpy.types, idname):
            problem("no menu %s" % idname)
        self.calls.append("menu " + idname)

    def template_list(self, list_type, list_id, data, prop, active_data, active_prop, **kw):
        if not hasattr(bpy.types, list_type):
            problem("no UIList %s" % list_type)
        for d, p in ((data, prop), (active_data, active_prop)):
            if p not in d.bl_rna.properties:
                problem("%s has no property %r" % (type(d).__name__, p))
        self.calls.append("template_list " + list_type)
        cls = getattr(bpy.types, list_type, None)
        if cls is not None:   # draw each item as Blender would
            for i, item in enumerate(getattr(data, prop)):
                cls.draw_item(cls, CONTEXT, Layout(self.calls), data, item, 0, active_data,
                              active_prop, i)


class Context:
    def __init__(self, obj):
        self.object = self.active_object = obj
        self.scene = bpy.context.scene
        self.mode = "OBJECT"


CONTEXT = None


def draw_all(obj, state):
    """Draws every panel, menu and appended draw function of the add-on for `obj`."""
    global CONTEXT
    CONTEXT = Context(obj)
    calls = []
    ui = S.addon.ui
    for cls in ui.CLASSES:
        if issubclass(cls, (bpy.types.Panel, bpy.types.Menu)) and hasattr(cls, "draw"):
            if issubclass(cls, bpy.types.Panel) and not cls.poll(CONTEXT):
                continue
            fake = type("Fake", (), {"layout": Layout(calls)})()
            cls.draw(fake, CONTEXT)
    for name, fn, everywhere in ui._APPENDS:
        if not hasattr(bpy.types, name):
            if not everywhere:
                continue
            problem("Blender %s has no %s to append to" % (bpy.app.version_string, name))
        fake = type("Fake", (), {"layout": Layout(calls)})()
        fn(fake, CONTEXT)
    for icon, what in [(m.icon, m.id) for m in S.methods.METHODS]:
        check_icon(icon, "method %s" % what)
    R.check("%s: the UI draws (%d layout calls) with no API problem" % (state, len(calls)),
            not PROBLEMS and len(calls) > 5, "\n  " + "\n  ".join(PROBLEMS))
    PROBLEMS.clear()
    return calls


def test_states():
    S.reset_scene()
    obj = S.make_grid()
    draw_all(obj, "no deformer")
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    calls = draw_all(obj, "ARAP unbound")
    R.check("the panel offers Bind", "operator deformkit.bind" in calls)
    d.material_group = "fixed"
    bpy.ops.deformkit.bind()
    calls = draw_all(obj, "ARAP bound, material group")
    R.check("the panel shows the material stiffness", "prop stiffness_scale" in calls)
    R.check("a converged result: no refining line", "label refining\u2026" not in calls)
    S.solver.cache._cache[(obj.name, d.uid)].pending = True  # as a budgeted drag update leaves it
    calls = draw_all(obj, "ARAP refining")
    R.check("a pending result: the panel says refining", "label refining\u2026" in calls)
    S.solver.cache._cache[(obj.name, d.uid)].pending = False
    for m in S.methods.METHODS:
        d.method = m.id
        for open_ in (False, True):   # the options box's Advanced section, both ways
            d.show_advanced = open_
            draw_all(obj, "%s options, Advanced %s" % (m.id, "open" if open_ else "closed"))
    d.method = "ARAP"
    d.status, d.status_is_error = "something failed", True
    draw_all(obj, "error status")
    arm = bpy.data.armatures.new("Rig")
    rig = bpy.data.objects.new("Rig", arm)
    bpy.context.scene.collection.objects.link(rig)
    d.handles[0].target = rig
    draw_all(obj, "armature handle")
    mod = S.geonodes.find_modifier(obj, d)
    obj.modifiers.remove(mod)
    draw_all(obj, "modifier removed")


def test_bind_warnings_in_the_panel():
    """A bound deformer whose native object warns (here a loose vertex, held at rest) shows the
    warning in its panel, not only in the bind's report, which vanishes."""
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    bpy.ops.deformkit.bind()
    text = lambda calls: " ".join(c[6:] for c in calls if c.startswith("label "))
    R.check("no warning in a clean bind's panel", "held at rest" not in text(draw_all(obj, "clean")))
    S.add_loose_vertex(obj, (5.0, 5.0, 5.0))
    bpy.ops.deformkit.bind()
    shown = text(draw_all(obj, "loose vertex"))
    R.check("the panel shows the loose-vertex warning: %r" % shown,
            "with no handle or fixed vertex is held at rest" in shown)


def test_add_modifier_menu():
    """Where Blender has the Add Modifier menu's Deform section (4.0+), DeformKit's methods are
    listed there for a mesh, each adding its deformer; for a curve, nothing."""
    S.reset_scene()
    obj = S.make_grid()
    menu = getattr(bpy.types, "OBJECT_MT_modifier_add_deform", None)
    if menu is None:
        R.check("no Deform section before 4.0 (Blender %s)" % bpy.app.version_string,
                bpy.app.version < (4, 0, 0))
        return
    ui = S.addon.ui
    R.check("DeformKit draws in the Deform section",
            ui._draw_modifier_add_deform in getattr(menu, "_dyn_ui_initialize", lambda: [])())
    calls = []
    ui._draw_modifier_add_deform(type("Fake", (), {"layout": Layout(calls)})(), Context(obj))
    got = [c for c in calls if c.startswith("operator deformkit.add_deformer")]
    R.check("every method listed: %d entries" % len(got), len(got) == len(S.methods.METHODS)
            and not PROBLEMS, (calls, PROBLEMS))
    curve = bpy.data.objects.new("Curve", bpy.data.curves.new("Curve", "CURVE"))
    calls = []
    ui._draw_modifier_add_deform(type("Fake", (), {"layout": Layout(calls)})(), Context(curve))
    R.check("nothing listed for a curve", calls == [], calls)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.deformkit.add_deformer(method=S.methods.METHODS[-1].id)
    R.check("the entry's operator adds the deformer",
            len(obj.deformkit.deformers) == 1 and
            S.geonodes.find_modifier(obj, obj.deformkit.deformers[0]) is not None)


R.run(test_states)
R.run(test_add_modifier_menu)
R.run(test_bind_warnings_in_the_panel)
R.finish()

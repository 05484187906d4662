"""What the add-on tells the artist (issue 17, items 7 and 8): option and enum item
descriptions, artist labels, the Advanced section of the options box, the deformer's name
across a method switch, status texts that follow the state (handles added, a sliced solve's
totals, convergence only where it means something), plurals and articles, wrapped long
statuses. Headless: panels are drawn into test_addon_ui's recording layout."""
import os
import re
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _setup as S  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_addon_texts")
text = S.addon.text
# the stand-in module (DEFORMKIT_MOCK=1) converges at once: no slices, no iteration cap
REAL_SOLVER = os.environ.get("DEFORMKIT_MOCK") != "1"


class Layout:
    """A stand-in UILayout that records what is drawn: `calls` holds (container path, kind,
    name) with kind 'prop', 'prop_search', 'label', 'operator', ...; containers (row, column,
    box, split) get their own path, so a test can tell where something was drawn."""

    def __init__(self, calls, path="root"):
        object.__setattr__(self, "calls", calls)
        object.__setattr__(self, "path", path)
        object.__setattr__(self, "n", 0)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)

    def _sub(self, *a, **kw):
        object.__setattr__(self, "n", self.n + 1)
        return Layout(self.calls, "%s/%d" % (self.path, self.n))

    row = column = box = split = column_flow = grid_flow = _sub

    def label(self, text="", icon=None, **kw):
        self.calls.append((self.path, "label", text))

    def prop(self, data, path, text=None, **kw):
        self.calls.append((self.path, "prop", path))

    def prop_search(self, data, path, *a, text=None, **kw):
        self.calls.append((self.path, "prop_search", path, text))

    def operator(self, idname, **kw):
        self.calls.append((self.path, "operator", idname))
        return type("Props", (), {})()

    def menu(self, idname, **kw):
        self.calls.append((self.path, "menu", idname))

    def template_list(self, *a, **kw):
        self.calls.append((self.path, "template_list", a[0]))

    def separator(self, *a, **kw):
        pass


class Context:
    def __init__(self, obj, region_width=None):
        self.object = self.active_object = obj
        self.scene = bpy.context.scene
        self.region = None if region_width is None else type("Region", (), {
            "width": region_width})()


def draw_panel(obj, region_width=None):
    calls = []
    fake = type("Fake", (), {"layout": Layout(calls)})()
    S.addon.ui.DEFORMKIT_PT_modifiers.draw(fake, Context(obj, region_width))
    return calls


def test_plural_and_article():
    R.check("plural: 1 handle, 2 handles, 0 handles",
            (text.plural(1, "handle"), text.plural(2, "handle"), text.plural(0, "handle"))
            == ("1 handle", "2 handles", "0 handles"))
    R.check("plural: 1 vertex, 3 vertices",
            (text.plural(1, "vertex"), text.plural(3, "vertex")) == ("1 vertex", "3 vertices"))
    R.check("article: an empty, an armature, a curve",
            (text.article("empty"), text.article("armature"), text.article("curve"))
            == ("an empty", "an armature", "a curve"))


def test_not_a_mesh_article():
    S.reset_scene()
    e = S.empty("Handle")
    bpy.context.view_layer.objects.active = e
    try:
        bpy.ops.deformkit.add_deformer(method="ARAP")
        msg = ""
    except RuntimeError as ex:
        msg = str(ex)
    R.check("a non-mesh object is 'an empty', not 'a empty'", "is an empty" in msg, msg)


def test_status_follows_handles():
    S.reset_scene()
    obj = S.make_grid()
    S.group(obj, "tip", [10, 11])
    e = S.empty("Tip")
    bpy.ops.deformkit.add_deformer(method="ARAP")
    d = obj.deformkit.deformers[0]
    R.check("new deformer: asks for a handle", "add a handle" in S.solver.status_text(d),
            S.solver.status_text(d))
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    for what, s in (("shown", S.solver.status_text(d)), ("stored", d.status)):
        R.check("after a handle is added the %s status says press Bind, not add handles"
                % what, "add a handle" not in s and "add handles" not in s
                and "press Bind" in s, s)
    bpy.ops.deformkit.remove_handle()
    R.check("after the last handle is removed it asks for a handle again",
            "add a handle" in S.solver.status_text(d), S.solver.status_text(d))
    # a bind tried without handles leaves its error; a handle added clears it
    try:
        bpy.ops.deformkit.bind()
    except RuntimeError:
        pass
    R.check("bind without handles: an error", d.status_is_error and "no handles" in d.status,
            d.status)
    bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
    R.check("a handle added clears the stale 'no handles' error",
            not d.status_is_error and "press Bind" in S.solver.status_text(d), d.status)
    bpy.ops.deformkit.bind()
    s = S.solver.status_text(d)
    R.check("bound with one handle: '1 handle', not '1 handles'",
            s == "bound: %d vertices, 1 handle" % len(obj.data.vertices), s)
    S.group(obj, "tip2", [60, 61])
    bpy.ops.deformkit.add_handle(vertex_group="tip2", target=S.empty("Tip2").name)
    s = S.solver.status_text(d)
    R.check("a handle added to a bound deformer: the shown count follows", "2 handles" in s, s)
    bpy.ops.deformkit.unbind()
    s = S.solver.status_text(d)
    R.check("unbound with handles: press Bind", s == "not bound: press Bind", s)


def test_sliced_solve_totals():
    """An interactive ARAP solve cut into the smallest slices (the budget shrunk; under -b
    handlers.refine() stands in for the timer; each slice is then a Newton step cut to one
    CG iteration): the panel's line gives the whole solve, its slices' iterations and time
    summed, and the solve ends at the minimum an uninterrupted solve reaches."""
    if not REAL_SOLVER:
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP", nx=30, ny=15)
    bpy.ops.deformkit.bind()
    key = (obj.name, d.uid)
    bind_T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
    budget = S.solver.budget.INTERACTIVE_BUDGET_MS
    S.handlers.force_interactive[0] = True
    S.solver.budget.INTERACTIVE_BUDGET_MS = 1e-9   # one iteration a slice
    try:
        e.location = (1.0, 0.1, 0.4)
        e.rotation_euler = (0.0, -0.3, 0.0)
        bpy.context.view_layer.update()
        seen = [dict(S.solver.runtime[key])]
        while S.solver.pending() and len(seen) < 500:
            S.handlers.refine()
            seen.append(dict(S.solver.runtime[key]))
    finally:
        S.solver.budget.INTERACTIVE_BUDGET_MS = budget
        S.handlers.force_interactive[0] = False
    rt = seen[-1]
    T = S.handles.transforms(obj, d, bpy.context.evaluated_depsgraph_get())
    ref, r = S.arap_reference(obj, d, handle, fixed, bind_T, T)
    steps = [b["iterations"] - a["iterations"] for a, b in zip(seen, seen[1:])]
    R.check("the solve took several slices (%d)" % len(seen),
            len(seen) > 2 and seen[0]["iterations"] == 1 and rt["slices"] == len(seen),
            [x["iterations"] for x in seen])
    R.check("every slice counted once in the total (%d iterations)" % rt["iterations"],
            all(k >= 1 for k in steps) and rt["iterations"] == 1 + sum(steps)
            and rt["converged"], (rt, steps[:20]))
    got = S.evaluated_positions(obj)
    R.check("it ends at the uninterrupted solve's minimum (energy within 1e-5)",
            abs(float(ref.energy(got)) - r.energy) <= 1e-5 * r.energy,
            (float(ref.energy(got)), r.energy))
    R.check("the time is summed over the slices",
            all(b["ms"] > a["ms"] for a, b in zip(seen, seen[1:])), [x["ms"] for x in seen])
    line = S.solver.solve_summary(obj, d)
    R.check("the panel's line gives the total", line == "last solve %.1f ms, %s"
            % (rt["ms"], text.plural(rt["iterations"], "iteration")), line)
    # the next drag starts a new solve: its own figures, not added to the last one's
    e.location = (1.0, 0.1, 0.45)
    bpy.context.view_layer.update()
    R.check("a new solve starts its own count", S.solver.runtime[key]["slices"] == 1,
            S.solver.runtime[key])


def test_convergence_wording():
    """'(not converged)' only for iterative methods that stopped at their cap; a direct
    method's line has no iterations and never says it."""
    for m in S.handle_methods():
        if m.iterative or not S.native.has_class(m.native_class):
            continue
        S.reset_scene()
        obj, d, e, fixed, handle = S.grid_setup(m.id)
        bpy.ops.deformkit.bind()
        e.location = (1.2, 0.0, 0.5)
        bpy.context.view_layer.update()
        line = S.solver.solve_summary(obj, d) or ""
        R.check("%s (direct): '%s' has a time, no iterations, no convergence" % (m.id, line),
                line.startswith("last solve") and "iteration" not in line
                and "converged" not in line, line)
    if not REAL_SOLVER:
        return
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    d.options.max_iterations = 1
    bpy.ops.deformkit.bind()
    e.location = (1.0, 0.1, 0.6)
    bpy.context.view_layer.update()
    line = S.solver.solve_summary(obj, d) or ""
    R.check("ARAP capped at 1 iteration: '%s'" % line,
            line.endswith("1 iteration (not converged)"), line)


def test_long_status_wraps():
    """A long error is drawn over several label lines, none longer than the region holds, and
    a wider region takes fewer lines; nothing is lost."""
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    long = ("handle 'DK Handle 1' overlaps the fixed group 'fixed' in 12 vertices (first: "
            "vertex 0): remove them from one group, or pick another Fixed group, then bind "
            "again; the modifier shows the rest shape until then")
    S.solver.set_status(d, long, True)
    lines = {}
    for w in (320, 900):
        labels = [c for c in draw_panel(obj, w) if c[1] == "label"]
        start = next(i for i, c in enumerate(labels) if long.startswith(c[2]))
        got = []
        for c in labels[start:]:
            got.append(c[2])
            if " ".join(got) == long:
                break
        lines[w] = got
        chars = S.addon.ui.wrap_width(Context(obj, w))
        R.check("region %d px: the status over %d lines of at most %d characters, all of it"
                % (w, len(got), chars), " ".join(got) == long
                and all(len(x) <= chars for x in got), got)
    R.check("a narrow region takes more lines (%d) than a wide one (%d)"
            % (len(lines[320]), len(lines[900])), len(lines[320]) > len(lines[900]) >= 1)


def test_name_follows_method():
    S.reset_scene()
    obj = S.make_grid()
    bpy.ops.deformkit.add_deformer(method="ARAP")
    bpy.ops.deformkit.add_deformer(method="ARAP")
    a, b = obj.deformkit.deformers
    mod = lambda d: S.geonodes.find_modifier(obj, d)  # noqa: E731
    R.check("two ARAP deformers: DeformKit ARAP and DeformKit ARAP.002",
            (a.name, b.name) == ("DeformKit ARAP", "DeformKit ARAP.002"), (a.name, b.name))
    b.method = "LAPLACIAN"
    R.check("ARAP -> Laplacian Edit renames the deformer and its modifier",
            b.name == "DeformKit Laplacian Edit" and mod(b).name == b.name,
            (b.name, mod(b).name))
    b.method = "FALLOFF"
    a.method = "FALLOFF"
    R.check("the new name is unique: DeformKit Falloff, DeformKit Falloff.002",
            (b.name, a.name) == ("DeformKit Falloff", "DeformKit Falloff.002")
            and mod(a).name == a.name, (b.name, a.name, mod(a).name))
    a.method = "ARAP"
    R.check("and back: DeformKit ARAP", a.name == "DeformKit ARAP", a.name)
    a.name = "Elbow bend"
    a.method = "LAPLACIAN"
    R.check("a name the user typed stays after a switch", a.name == "Elbow bend", a.name)
    mod(b).name = "My modifier"
    b.method = "EIGEN"
    R.check("the deformer's auto name follows; a modifier the user renamed keeps its name",
            b.name == "DeformKit Eigen Deformation" and mod(b).name == "My modifier",
            (b.name, mod(b).name))


# The stored identifiers of every enum option: files saved before keep loading only while
# these stay (labels and descriptions may change).
STORED_IDS = {
    ("ARAP", "energy"): ("spokes", "spokes_and_rims"),
    ("ARAP", "weights"): ("cotangent", "clamped_cotangent", "uniform"),
    ("ARAP", "acceleration"): ("anderson", "none", "newton"),
    ("LAPLACIAN", "weights"): ("cotangent", "uniform"),
    ("LAPLACIAN", "detail"): ("fixed", "membrane", "local_frame"),
    ("LAPLACIAN", "constraints"): ("hard", "soft"),
    ("FALLOFF", "distance"): ("hops", "euclidean", "geodesic", "dijkstra"),
    ("EMBEDDED", "nodes"): ("surface", "vertices"),
    ("EMBEDDED", "distance"): ("euclidean", "geodesic"),
    ("EIGEN", "laplacian"): ("cotangent", "belkin_sun_wang"),
    ("LINEAR_RECONSTRUCTION", "material_mode"): ("interpolate", "smooth"),
    ("LATTICE", "interpolation"): ("bspline", "linear", "bernstein"),
    ("LATTICE", "outside"): ("extend", "clamp", "still"),
    ("CAGE", "coordinates"): ("mean_value", "green"),
    ("CAGE", "evaluation"): ("auto", "exact", "grid"),
    ("CAGE", "weights"): ("double", "single"),
    ("SHEPARD", "interpolate"): ("transforms", "displacements"),
    ("SHEPARD", "distance"): ("euclidean", "geodesic"),
    ("SKINNING", "blend"): ("linear", "dual_quaternion"),
    ("SHAPE_MATCHING", "mode"): ("rigid", "linear", "quadratic"),
    ("SHAPE_MATCHING", "clusters"): ("cubes", "parts"),
    ("SHAPE_MATCHING", "integrator"): ("semi_implicit_euler", "explicit_euler", "implicit_euler",
                                       "rk4"),
    ("SHAPE_BLEND", "rotations"): ("consistent", "principal"),
    ("SHAPE_BLEND", "stretches"): ("linear", "log"),
    ("SHAPE_BLEND", "edge_weights"): ("clamped_cotangent", "cotangent", "uniform"),
    ("SHEPARD", "neighbourhood"): ("all", "nearest", "radius"),
    ("VOLUME_ARAP", "acceleration"): ("anderson", "none", "newton"),
}
# the solver's words the issue found in the UI, which an artist cannot act on
SOLVER_WORDS = ("Tikhonov", "Regularization", "Material Stiffness", "CG Iterations",
                "Frame Iterations", "Constraint Weight", "Eigenvectors")


def test_descriptions_and_labels():
    """From the registered properties (what the UI shows): every option and every enum item
    of every method has a label and a real description; no solver word is a label; enum
    identifiers are the stored ones."""
    S.reset_scene()
    obj = S.make_grid()
    bpy.ops.deformkit.add_deformer(method="ARAP")
    d = obj.deformkit.deformers[0]
    missing, solver_words, ids = [], [], {}
    for m in S.methods.METHODS:
        rna = getattr(d, S.methods.options_attr(m.id)).bl_rna
        for o in m.options:
            p = rna.properties[o.name]
            if not p.name or len(p.description.split()) < 4:
                missing.append("%s.%s" % (m.id, o.name))
            if any(w in p.name for w in SOLVER_WORDS):
                solver_words.append("%s.%s %r" % (m.id, o.name, p.name))
            if o.type == "ENUM":
                ids[(m.id, o.name)] = tuple(i.identifier for i in p.enum_items)
                for i in p.enum_items:
                    if not i.name or len(i.description.split()) < 4:
                        missing.append("%s.%s item %s" % (m.id, o.name, i.identifier))
                    if i.name in ("None", "") or any(w in i.name for w in SOLVER_WORDS):
                        solver_words.append("%s.%s item %r" % (m.id, o.name, i.name))
    R.check("every option and enum item of every method has a description", not missing,
            missing)
    R.check("no label or item name in the solver's words ('Tikhonov', 'None', ...)",
            not solver_words, solver_words)
    R.check("enum identifiers unchanged (saved files still load)", ids == STORED_IDS, ids)
    items = d.bl_rna.properties["method"].enum_items
    R.check("every method has a description", all(i.description for i in items))
    arap = d.options_arap.bl_rna.properties["acceleration"].enum_items
    R.check("ARAP's plain solver is not called 'None'", arap["none"].name == "Basic",
            arap["none"].name)


def test_material_group_label():
    """The Material group's label in the panel speaks the method's language."""
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    want = {"ARAP": "Stiffness", "LINEAR_RECONSTRUCTION": "Material", "SHAPE_MATCHING": "Hold",
            "VOLUME_ARAP": "Stiffness"}
    for m in S.methods.METHODS:
        d.method = m.id
        got = [c[3] for c in draw_panel(obj) if c[1:3] == ("prop_search", "material_group")]
        uses = bool({"stiffness", "material", "paint"} & set(m.maps))
        R.check("%s: the material group is %s" % (
            m.id, "labelled %r" % want.get(m.id) if uses else "not drawn"),
            got == ([want[m.id]] if uses else []), got)


def test_advanced_section():
    """Expert options are drawn only in the Advanced section: not at all while it is
    collapsed, after its toggle and in their own column when open; everyday ones always in
    the main column."""
    S.reset_scene()
    obj, d, e, fixed, handle = S.grid_setup("ARAP")
    d.material_group = "fixed"
    for m in S.methods.METHODS:
        d.method = m.id
        opts = d.options

        def applies(o):  # Option.shown_if: drawn only for some values of another option
            return not o.shown_if or getattr(opts, o.shown_if[0]) in o.shown_if[1]
        names = [o.name for o in m.options]
        everyday = [o.name for o in m.options if not o.advanced and applies(o)]
        expert = [o.name for o in m.options if o.advanced and applies(o)]
        d.show_advanced = False
        calls = [c for c in draw_panel(obj) if c[1] in ("prop", "prop_search")]
        drawn = [c[2] for c in calls if c[2] in names]
        R.check("%s collapsed: the everyday options drawn (%s), no expert one"
                % (m.id, ", ".join(everyday)),
                drawn == everyday and ("show_advanced" in [c[2] for c in calls]) == bool(expert),
                drawn)
        if not expert:
            continue
        d.show_advanced = True
        calls = [c for c in draw_panel(obj) if c[1] in ("prop", "prop_search")]
        at = [c[2] for c in calls].index("show_advanced")
        main = {c[0] for c in calls if c[2] in everyday}
        adv = {c[0] for c in calls if c[2] in expert}
        R.check("%s open: the expert options (%s) after the Advanced toggle, in their own "
                "column" % (m.id, ", ".join(expert)),
                [c[2] for c in calls[at + 1:] if c[2] in expert] == expert
                and len(adv) == 1 and not adv & main, (calls, main, adv))
    arap = S.methods.get("ARAP")
    R.check("ARAP keeps tolerance, iteration cap and solver in Advanced",
            all(o.advanced for o in arap.options
                if o.name in ("tolerance", "max_iterations", "acceleration", "cg_iterations")))
    R.check("every iterative method's iteration cap is Advanced",
            all(next(o for o in m.options if o.name == m.iteration_cap).advanced
                for m in S.methods.METHODS if m.iterative))


def test_no_unplural_counts_in_source():
    """No user-facing string of the add-on formats a count before a plural noun ("%d handles"
    says "1 handles") or writes "a %s" before a word that may start with a vowel: counts go
    through text.plural, articles through text.article."""
    here = os.path.dirname(S.addon.__file__)
    bad = []
    files = sorted(os.path.relpath(os.path.join(r, f), here) for r, _, fs in os.walk(here)
                   for f in fs)
    for f in files:
        if not f.endswith(".py") or f == "pc2.py":  # pc2: the file format's own errors
            continue
        src = open(os.path.join(here, f), encoding="utf-8").read()
        for mt in re.finditer(r"%d (handles|vertices|iterations|frames|faces|nodes|values|"
                              r"points|samples|groups|edges)\b|\b(is|as) a %s", src):
            line = src.count("\n", 0, mt.start()) + 1
            bad.append("%s:%d: %s" % (f, line, mt.group(0)))
    R.check("no '%d <plural>' or 'is a %s' in the add-on's strings", not bad, bad)


R.run(test_plural_and_article)
R.run(test_not_a_mesh_article)
R.run(test_status_follows_handles)
R.run(test_sliced_solve_totals)
R.run(test_convergence_wording)
R.run(test_long_status_wraps)
R.run(test_name_follows_method)
R.run(test_descriptions_and_labels)
R.run(test_material_group_label)
R.run(test_advanced_section)
R.run(test_no_unplural_counts_in_source)
R.finish()

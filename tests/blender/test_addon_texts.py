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


R.run(test_plural_and_article)
R.run(test_not_a_mesh_article)
R.run(test_status_follows_handles)
R.finish()

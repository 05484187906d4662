"""Show Graph: a bound deformer's graph drawn in the 3D viewport, as Blender draws a lattice
cage (embedded deformation's nodes and edges; a method opts in with `Method.graph`).

Each node is drawn where eq. 1 takes it, g_j + factor t_j (at the deformer's current Factor,
so the graph sits on the mesh as shown), in world space, on top of the mesh. The drawing
reads the solver's cached native object only; it never binds or solves, and a deformer
that is not bound draws nothing. A failure while drawing is printed once, never raised
(a draw callback that raises would repeat on every redraw).
"""
import bpy
import numpy as np

from . import compat, geonodes, methods, solver

NODE_COLOR = (1.0, 0.55, 0.1, 1.0)
EDGE_COLOR = (1.0, 0.8, 0.3, 0.8)
_state = {"handle": None, "draws": 0, "error": None}


def graph_lines(obj, d):
    """(points, edges) of a bound deformer whose method draws a graph and whose Show Graph
    is on: points (n_nodes x 3, world space) and edges (n_edges x 2 int32); else None."""
    m = methods.get(d.method)
    if not m.graph or not getattr(d.options, "show_graph", False) or not d.bound:
        return None
    e = solver.cache._cache.get((obj.name, d.uid))
    if e is None or e.native is None:
        return None
    if (e.worker is not None and e.worker.thread.is_alive()) or solver.rebind._in_place_rebind(
            (obj.name, d.uid)) is not None:
        # the object is solving (solver.workers._Worker) or re-binding for new groups
        # (solver.GroupsRebindJob) in a worker thread: the last graph drawn
        return e.graph_shown
    g = np.asarray(e.native.nodes, dtype=np.float64)
    t = np.asarray(e.native.transforms, dtype=np.float64)[:, 9:12]
    local = g + geonodes.factor(obj, d) * t
    mw = np.array(obj.matrix_world, dtype=np.float64)
    e.graph_shown = (local @ mw[:3, :3].T + mw[:3, 3], np.asarray(e.native.edges, dtype=np.int32))
    return e.graph_shown


EDGE_WIDTH = 1.5   # pixels
NODE_SIZE = 7.0    # pixels


def draw_graphs(graphs):
    """Draws each (points, edges) of `graphs` (graph_lines' results) into the bound frame
    buffer with the current view and projection matrices, on top of what is there."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    lines, points = compat.line_shader(), compat.point_shader()
    viewport = gpu.state.viewport_get()
    gpu.state.depth_test_set("NONE")
    gpu.state.blend_set("ALPHA")
    for pts, edges in graphs:
        pos = pts.astype(np.float32).tolist()
        if len(edges):
            lines.bind()
            lines.uniform_float("viewportSize", (float(viewport[2]), float(viewport[3])))
            lines.uniform_float("lineWidth", EDGE_WIDTH)
            lines.uniform_float("color", EDGE_COLOR)
            batch_for_shader(lines, "LINES", {"pos": pos},
                             indices=edges.tolist()).draw(lines)
        gpu.state.point_size_set(NODE_SIZE)
        points.bind()
        points.uniform_float("color", NODE_COLOR)
        batch_for_shader(points, "POINTS", {"pos": pos}).draw(points)
    gpu.state.point_size_set(1.0)
    gpu.state.blend_set("NONE")


def _draw():
    try:
        graphs = []
        for obj in bpy.context.visible_objects:
            if obj.type != "MESH" or not hasattr(obj, "deformkit"):
                continue
            for d in obj.deformkit.deformers:
                r = graph_lines(obj, d)
                if r is not None and len(r[0]):
                    graphs.append(r)
        if not graphs:
            return
        draw_graphs(graphs)
        _state["draws"] += 1
    except Exception as ex:  # noqa: BLE001 (never raise from a draw callback)
        if _state["error"] is None:
            _state["error"] = "%s: %s" % (type(ex).__name__, ex)
            print("DeformKit: Show Graph could not draw:", _state["error"])


def register():
    if _state["handle"] is None:
        _state["handle"] = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW",
                                                                  "POST_VIEW")


def unregister():
    if _state["handle"] is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_state["handle"], "WINDOW")
        _state["handle"] = None

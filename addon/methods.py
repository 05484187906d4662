"""The data-driven method registry.

Adding a deformation method to the add-on = one native class in `deformkit` + one `Method`
entry here (its options become properties and a panel automatically; `draw` is optional).

Each option maps to a keyword of the native constructor (`kw`), or is consumed by the add-on
(`kw=None`, e.g. how weight paint is turned into per-vertex stiffness).
"""

from dataclasses import dataclass, field
from typing import Any, Callable, Optional


@dataclass
class Option:
    name: str                    # property name (and constructor keyword unless kw given)
    type: str                    # 'ENUM' | 'INT' | 'FLOAT' | 'BOOL' | 'GROUP' (a vertex
                                 # group's name, read by the add-on: kw must be None)
    default: Any
    label: str = ""
    description: str = ""
    items: tuple = ()            # ENUM: ((id, label, description), ...)
    min: Optional[float] = None
    max: Optional[float] = None
    kw: Optional[str] = "same"   # constructor keyword; "same" = name; None = add-on only
    bind_time: bool = True       # True: a change re-binds; False: used at solve time only
    # the deformer setting (a group name) that must be set for the option to matter; the
    # panel hides the option otherwise (e.g. the material stiffness without a material group)
    shown_with: Optional[str] = None

    @property
    def keyword(self):
        return self.name if self.kw == "same" else self.kw


@dataclass
class Method:
    id: str                      # enum identifier, stored in files: never rename
    label: str                   # shown in the UI and used as the modifier name
    native_class: str            # attribute of the `deformkit` module
    description: str
    options: list = field(default_factory=list)
    # What the method consumes from Blender, beyond the mesh, the handles' groups and targets
    # and the Region and Fixed groups that every method takes:
    # which vertex-group maps: 'stiffness' (the material group's weights become the
    # per-vertex `stiffness` keyword), 'material' (they become the per-edge `material` map
    # of linear reconstruction: solver.material_map), 'handle_weights' (soft handles) and/or
    # 'cut' (two
    # GROUP options become the `cut=(group_a, group_b)` keyword: section 7 of Sumner et al.)
    maps: tuple = ()
    # 'cut' map: the two GROUP options holding the cut's sides
    cut_options: Optional[tuple] = None
    # 'stiffness' map: the option holding the stiffness where the material weight is 1
    # (weight 0 gives 1, linear in between)
    stiffness_option: Optional[str] = None
    # solve keywords that make a frame's result depend only on that frame (cold start)
    cold_solve: dict = field(default_factory=dict)
    # solve keywords for interactive updates
    warm_solve: dict = field(default_factory=dict)
    icon: str = "MOD_MESHDEFORM"
    draw: Optional[Callable] = None  # draw(layout, options_pointer) replaces the generic one
    # iterative methods whose solve takes max_iterations and reports `converged`: while the
    # user drags in the UI they get a time budget per update, and the add-on finishes the
    # solve from a timer once the handles stop (see solver.solve / handlers.refine)
    iterative: bool = False
    # iterative methods: the option capping the iterations of one solve (the budgeted
    # slices of an interactive solve add up to at most that many)
    iteration_cap: Optional[str] = None
    # iterative methods whose iterations are iterative themselves (ARAP's Newton steps: CG
    # iterations): the option, also a solve keyword for one call, holding their inner count,
    # and the (option, value) under which it applies. A budgeted slice that cannot fit one
    # full iteration takes one with fewer inner iterations (solver._budget)
    inner_iterations: Optional[str] = None
    inner_when: Optional[tuple] = None
    # False: the method also deforms meshes without faces (vertex clouds)
    needs_faces: bool = True
    # True: the native object has `nodes`, `edges` and `transforms` (a deformation graph)
    # and a BOOL option `show_graph` lets the viewport draw it (overlay.py)
    graph: bool = False
    # True: the native object has `update_source(positions)`; the method follows an input
    # that the modifiers and shape keys above it animate (solver.moved_input): each update
    # re-solves on that input, with the handles' edit (their displacement since the bind)
    # added to where the input puts the handle vertices (section 5 of Sumner et al.)
    follows_input: bool = False
    # solve keywords of a fast preview (eigen deformation's Steps 1-2): interactive updates
    # solve with them and stay pending; the timer in handlers.py gives the full result once
    # the handles have stopped for PREVIEW_SETTLE_S
    preview: dict = field(default_factory=dict)
    # True: the Region group, when set, is the region the handle moves (eigen deformation's
    # R) and goes to the native handles, with the first handle's transform
    region_is_handle: bool = False
    # True: the native constructor takes progress=callable(fraction) -> stop; the UI bind
    # shows the fraction and Esc stops the native work (solver.BindJob)
    bind_progress: bool = False


def _e(*ids):
    return tuple((i, i.replace("_", " ").title(), "") for i in ids)


METHODS = [
    Method(
        id="ARAP",
        label="ARAP",
        native_class="ARAP",
        description="As-rigid-as-possible: keeps local shape, bends and twists naturally",
        icon="MOD_SIMPLEDEFORM",
        maps=("stiffness",),
        stiffness_option="stiffness_scale",
        cold_solve={"warm_start": False},
        warm_solve={"warm_start": True},
        iterative=True,
        iteration_cap="max_iterations",
        inner_iterations="cg_iterations",
        inner_when=("acceleration", "newton"),
        options=[
            Option("energy", "ENUM", "spokes", "Energy", "Spokes (classic) or spokes and rims",
                   items=_e("spokes", "spokes_and_rims")),
            # default = the native default: negative cotangent weights make the energy
            # indefinite on real meshes (docs/methods/arap.md); item order is stored in files
            Option("weights", "ENUM", "clamped_cotangent", "Weights", "Edge weights of the energy",
                   items=_e("cotangent", "clamped_cotangent", "uniform")),
            Option("max_iterations", "INT", 100, "Max Iterations",
                   "Iterations (Newton steps, or local/global iterations) per solve",
                   min=1, max=100000),
            Option("tolerance", "FLOAT", 1e-6, "Tolerance",
                   "Stop when a local/global step would change the energy by less than this "
                   "fraction", min=0.0, max=1.0),
            # item order is stored in files: new items go last. Default: Newton (faster to
            # convergence and closer to the minimum, docs/methods/arap.md)
            Option("acceleration", "ENUM", "newton", "Solver",
                   "Newton steps (default), or local/global iterations with Anderson "
                   "acceleration or without",
                   items=(("anderson", "Anderson", "Local/global iterations, Anderson-accelerated"),
                          ("none", "None", "Plain local/global iterations (the paper's)"),
                          ("newton", "Newton", "Inexact Newton steps: fewer, costlier iterations "
                                               "that reach the minimum's bending modes"))),
            Option("cg_iterations", "INT", 12, "CG Iterations",
                   "Newton: conjugate-gradient iterations (Hessian products) per step",
                   min=1, max=100),
            Option("stiffness_scale", "FLOAT", 10.0, "Material Stiffness",
                   "Stiffness where the material group's weight is 1 (weight 0 gives 1)",
                   min=0.001, max=1e6, kw=None, shown_with="material_group"),
        ],
    ),
    Method(
        id="LAPLACIAN",
        label="Laplacian Edit",
        native_class="LaplacianEdit",
        description="Laplacian surface editing: one linear solve per update",
        icon="MOD_SMOOTH",
        maps=("handle_weights",),
        options=[
            Option("weights", "ENUM", "cotangent", "Weights", "Laplacian weights",
                   items=_e("cotangent", "uniform")),
            Option("detail", "ENUM", "local_frame", "Detail",
                   "How surface detail is carried along",
                   items=_e("fixed", "membrane", "local_frame")),
            Option("constraints", "ENUM", "hard", "Constraints", "Hard or least-squares handles",
                   items=_e("hard", "soft")),
            Option("constraint_weight", "FLOAT", 1.0, "Constraint Weight",
                   "Weight of soft constraints (and of handle vertices with weight < 1)",
                   min=1e-6, max=1e6),
            Option("tikhonov", "FLOAT", 0.0, "Regularization", "Tikhonov regularization",
                   min=0.0, max=1e6),
            Option("local_frame_iterations", "INT", 1, "Frame Iterations",
                   "Local frame: frame updates after the first solve", min=0, max=1000),
        ],
    ),
    Method(
        id="FALLOFF",
        label="Falloff",
        native_class="Falloff",
        description="Attenuated handle displacement by distance from the handle",
        icon="SMOOTHCURVE",
        maps=("handle_weights",),
        options=[
            Option("distance", "ENUM", "hops", "Distance", "How distance to a handle is measured",
                   items=_e("hops", "euclidean", "geodesic", "dijkstra")),
            Option("range", "FLOAT", 0.0, "Range",
                   "Falloff range: edges for hops, else a length (0: 10 hops or 10 mean edge "
                   "lengths)", min=0.0, max=1e9),
            Option("k", "FLOAT", 0.0, "Shape", "Falloff shape exponent", min=-100.0, max=100.0),
        ],
    ),
]

METHODS.append(Method(
    id="EMBEDDED",
    label="Embedded Deformation",
    native_class="EmbeddedDeformation",
    description="Deformation graph (Sumner et al. 2007): a few hundred nodes carry the "
                "shape, each an affine transformation kept close to a rotation; handles "
                "pull as soft constraints",
    icon="MOD_LATTICE",
    maps=("cut",),
    cut_options=("cut_a", "cut_b"),
    cold_solve={"warm_start": False},
    warm_solve={"warm_start": True},
    iterative=True,
    iteration_cap="max_iterations",
    needs_faces=False,
    graph=True,
    follows_input=True,
    options=[
        Option("n_nodes", "INT", 200, "Nodes", "Graph nodes sampled on the surface",
               min=5, max=100000),
        Option("nodes", "ENUM", "surface", "Node Source",
               "Where the graph's nodes come from",
               items=(("surface", "Surface", "Uniform samples of the surface (the paper's)"),
                      ("vertices", "Vertices", "Mesh vertices (a graph that rides along an "
                                               "animated mesh)"))),
        Option("k", "INT", 4, "Nearest Nodes", "Nodes that move each vertex", min=1, max=16),
        Option("distance", "ENUM", "euclidean", "Influence",
               "How a vertex's nearest nodes are found",
               items=(("euclidean", "Euclidean", "Straight-line distance in space (the "
                                                 "paper's)"),
                      ("geodesic", "Geodesic", "Distance along the surface, so that a hand "
                                               "node does not move the leg it lies against "
                                               "(needs faces)"))),
        Option("cut_a", "GROUP", "", "Cut Side A",
               "With Cut Side B: no node near this vertex group moves the other, and no "
               "graph edge joins them (the paper's stroke between a hand and a leg)", kw=None),
        Option("cut_b", "GROUP", "", "Cut Side B", "The other side of the cut", kw=None),
        Option("w_rot", "FLOAT", 1.0, "Rigidity", "Weight of the rotation term", min=1e-6,
               max=1e6),
        Option("w_reg", "FLOAT", 10.0, "Smoothness", "Weight of the regularization term",
               min=1e-6, max=1e6),
        Option("w_con", "FLOAT", 100.0, "Handle Pull", "Weight of the handle constraints",
               min=1e-6, max=1e9),
        Option("max_iterations", "INT", 30, "Max Iterations", "Gauss-Newton iterations",
               min=1, max=10000),
        Option("tolerance", "FLOAT", 1e-6, "Tolerance", "epsilon of the stopping tests",
               min=1e-15, max=1.0),
        Option("show_graph", "BOOL", False, "Show Graph",
               "Draw the deformation graph's nodes and edges in the viewport",
               kw=None, bind_time=False),
    ],
))

METHODS.append(Method(
    id="EIGEN",
    label="Eigen Deformation",
    native_class="EigenDeformation",
    description="Eigen deformation (Dey, Ranjan & Wang): a smooth fit with the mesh's "
                "Laplace-Beltrami eigenvectors moves the handle's region, and the details "
                "are added back in local frames",
    icon="MOD_WAVE",
    preview={"preview": True},
    region_is_handle=True,
    bind_progress=True,
    options=[
        Option("n_eigenvectors", "INT", 0, "Eigenvectors",
               "Eigenvectors of the fit (0: automatic, 8, 50 or 300 from the region's size; "
               "fewer bend more globally)", min=0, max=2000),
        Option("refine", "INT", 300, "Refinement",
               "Eigenvectors of the second iteration that rebuilds the details when fewer "
               "are used (0: one iteration)", min=0, max=2000),
        # item order is stored in files: new items go last
        Option("laplacian", "ENUM", "cotangent", "Laplacian",
               "Whose eigenvectors carry the deformation",
               items=(("cotangent", "Cotangent", "Cotangent weights with Voronoi areas: "
                                                 "binds fastest (the default)"),
                      ("belkin_sun_wang", "Belkin-Sun-Wang",
                       "The paper's mesh-Laplacian: a heat kernel over nearby vertices in "
                       "space; slower to bind, about the same shapes"))),
    ],
))

METHODS.append(Method(
    id="LINEAR_RECONSTRUCTION",
    label="Linear Reconstruction",
    native_class="LinearReconstruction",
    description="Linear reconstruction from discrete fundamental forms (Wang, Liu & Tong; "
                "Li): edge lengths and dihedral angles kept by one linear solve for positions "
                "and triangle frames",
    icon="MOD_TRIANGULATE",
    maps=("material",),
    options=[
        Option("softness", "FLOAT", 1.0, "Softness",
               "How much easier to fold the painted material is (0: as built, 1: softest)",
               min=0.0, max=1.0, kw=None, shown_with="material_group"),
        Option("material_mode", "ENUM", "interpolate", "Material Paint",
               "How the Material group's weight paint becomes the material map",
               items=(("interpolate", "Interpolate", "A smooth (harmonic) map through the "
                                                     "painted vertices, as built at the "
                                                     "handles and the fixed part"),
                      ("smooth", "Smooth", "The raw paint, smoothed along the surface")),
               kw=None, shown_with="material_group"),
        Option("smooth_iterations", "INT", 10, "Smoothing",
               "Smooth: averaging passes over the raw paint", min=0, max=1000, kw=None,
               shown_with="material_group"),
        Option("show_material", "BOOL", False, "Show Material",
               "Show the material map as the mesh's active colour attribute (Solid mode, "
               "Attribute colouring): grey as built, yellow softest",
               kw=None, bind_time=False, shown_with="material_group"),
        Option("w", "FLOAT", 1.0, "Bending Weight",
               "Weight of the frame (bending) term against the edge (stretching) term",
               min=1e-6, max=1e6),
        Option("orientation", "BOOL", False, "Turn Handle Faces",
               "A rotated handle target also turns the faces of its group"),
    ],
))

BY_ID = {m.id: m for m in METHODS}


def _check_registry():
    """Every field that names an option names one of the method's options."""
    for m in METHODS:
        names = {o.name for o in m.options}
        for field_name in ("stiffness_option", "iteration_cap", "inner_iterations"):
            ref = getattr(m, field_name)
            if ref is not None and ref not in names:
                raise ValueError("%s.%s names %r, which is not one of its options"
                                 % (m.id, field_name, ref))
        if ("stiffness" in m.maps) != (m.stiffness_option is not None):
            raise ValueError("%s: a 'stiffness' map needs a stiffness_option" % m.id)
        groups = {o.name for o in m.options if o.type == "GROUP"}
        if any(o.type == "GROUP" and o.kw is not None for o in m.options):
            raise ValueError("%s: GROUP options are read by the add-on (kw=None)" % m.id)
        if ("cut" in m.maps) != (m.cut_options is not None) or (
                m.cut_options is not None and (len(m.cut_options) != 2
                                               or not set(m.cut_options) <= groups)):
            raise ValueError("%s: a 'cut' map needs cut_options naming two GROUP options"
                             % m.id)
        if m.graph and "show_graph" not in {o.name for o in m.options if o.type == "BOOL"}:
            raise ValueError("%s: a method that draws a graph needs a BOOL show_graph" % m.id)
        if m.iterative and m.iteration_cap is None:
            raise ValueError("%s: an iterative method needs an iteration_cap option" % m.id)
        if m.inner_iterations is not None and (
                not m.iterative or (m.inner_when is not None and m.inner_when[0] not in names)):
            raise ValueError("%s: inner_iterations belong to an iterative method, and "
                             "inner_when must name one of its options" % m.id)


_check_registry()


def get(method_id):
    return BY_ID[method_id]


def enum_items():
    return [(m.id, m.label, m.description, m.icon, i) for i, m in enumerate(METHODS)]


def options_attr(method_id):
    """Name of the PointerProperty on a deformer holding this method's options."""
    return "options_" + method_id.lower()


def constructor_kwargs(method, opts):
    """Constructor keywords from an options PropertyGroup (only the ones mapped to the API)."""
    kw = {}
    for o in method.options:
        if o.keyword is not None and o.bind_time:
            kw[o.keyword] = getattr(opts, o.name)
    return kw


def solve_kwargs(method, opts, cold):
    # The add-on never shows a method's energy: every solve skips its evaluation (a pass
    # over the operator: ~0.4 ms for Laplacian editing, ~35 ms for linear reconstruction's
    # 300k unknowns on the armadillo, ten times its drag).
    kw = {"energy": False}
    kw.update(method.cold_solve if cold else method.warm_solve)
    for o in method.options:
        if o.keyword is not None and not o.bind_time:
            kw[o.keyword] = getattr(opts, o.name)
    return kw


def signature(method, opts):
    """Bind-time settings as a hashable tuple (a change re-binds)."""
    return (method.id,) + tuple(
        (o.name, getattr(opts, o.name)) for o in method.options if o.bind_time)

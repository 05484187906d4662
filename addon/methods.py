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
    type: str                    # 'ENUM' | 'INT' | 'FLOAT' | 'BOOL' | 'STRING' | 'GROUP' (a vertex
                                 # group's name, read by the add-on: kw must be None)
    default: Any
    label: str = ""              # shown in the UI: the artist's word, not the solver's
    description: str = ""        # the tooltip: what it does to the result, when to change it
    items: tuple = ()            # ENUM: ((id, label, description), ...); ids are stored in
                                 # files (never rename), labels and descriptions are free
    min: Optional[float] = None
    max: Optional[float] = None
    kw: Optional[str] = "same"   # constructor keyword; "same" = name; None = add-on only
    bind_time: bool = True       # True: a change re-binds; False: used at solve time only
    # the deformer setting (a group name) that must be set for the option to matter; the
    # panel hides the option otherwise (e.g. the material stiffness without a material group)
    shown_with: Optional[str] = None
    # True: an expert knob (tolerances, iteration caps, solver internals, energy weights),
    # drawn in the options box's collapsed Advanced section (ui.draw_options)
    advanced: bool = False
    # (option name, values): the option matters, and is drawn, only while that other option
    # has one of these values (Falloff's Range in edges with Edge Steps only)
    shown_if: Optional[tuple] = None
    subtype: str = "NONE"        # FLOAT: Blender's property subtype ('DISTANCE': scene units)

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
    # of linear reconstruction: solver.material_map), 'paint' (they become the per-vertex
    # `paint_keyword`, as they are), 'handle_weights' (soft handles) and/or
    # 'cut' (two
    # GROUP options become the `cut=(group_a, group_b)` keyword: section 7 of Sumner et al.)
    maps: tuple = ()
    # extra constructor keywords computed at bind: bind_args(options, rest positions n x 3,
    # the constraint keywords (handles, fixed, ...), the native Mesh) -> dict
    bind_args: Optional[Callable] = None
    # 'stiffness' or 'material' map: the panel's label of the Material group (the deformer's
    # material_group), in the method's terms ("Stiffness" for ARAP)
    material_label: str = "Material"
    # 'cut' map: the two GROUP options holding the cut's sides
    cut_options: Optional[tuple] = None
    # 'stiffness' map: the option holding the stiffness where the material weight is 1
    # (weight 0 gives 1, linear in between)
    stiffness_option: Optional[str] = None
    # 'paint' map: the constructor keyword that takes the Material group's weights as they
    # are, one value per vertex (0 where the group has none): a simulation's attachment
    paint_keyword: Optional[str] = None
    # painted per-vertex factors: {GROUP option: constructor keyword}; the group's weights
    # become the keyword's values, 1 where the group has none (a simulation's stiffness,
    # damping and squash, painted)
    group_maps: dict = field(default_factory=dict)
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
    # full iteration takes one with fewer inner iterations (solver.budget._budget)
    inner_iterations: Optional[str] = None
    inner_when: Optional[tuple] = None
    # False: the method also deforms meshes without faces (vertex clouds)
    needs_faces: bool = True
    # True: the native object has `nodes`, `edges` and `transforms` (a deformation graph)
    # and a BOOL option `show_graph` lets the viewport draw it (overlay.py)
    graph: bool = False
    # True: the native object has `update_source(positions)`; the method follows an input
    # that the modifiers and shape keys above it animate (animated_input.moved_input): each update
    # re-solves on that input, with the handles' edit (their displacement since the bind)
    # added to where the input puts the handle vertices (section 5 of Sumner et al.)
    follows_input: bool = False
    # solve keywords of a fast preview (eigen deformation's Steps 1-2): interactive updates
    # solve with them and stay pending; the timer in handlers.py gives the full result once
    # the handles have stopped for PREVIEW_SETTLE_S
    preview: dict = field(default_factory=dict)
    # True: the Region group, when set, is the region the handle moves (eigen deformation's
    # R) and goes to the native handles, with the first handle's transform; region_kw: the
    # bind keywords that say so to the native class
    region_is_handle: bool = False
    region_kw: dict = field(default_factory=dict)
    # What the panel checks of a settled result, to say when this method cannot do the edit
    # well (solver.fit_warning): "handles" (handles met approximately: how far the handle
    # vertices are from their targets, against the move), "stretch" (a linear method: how
    # many edges the result stretches by more than half), or None (nothing to say)
    fit_check: Optional[str] = None
    # ... and what the warning suggests instead (a method's label)
    better_method: str = "ARAP"
    # True: the native constructor takes progress=callable(fraction) -> stop (fraction a
    # deformkit.BindProgress: a float with the phase's name in .phase); the UI bind shows
    # the phase and fraction, and Esc stops the native work at its next report
    # (solver.BindJob)
    bind_progress: bool = False
    # True: the native rebind takes progress= as well (a groups change on a big mesh
    # re-binds in place in a worker thread, solver.GroupsRebindJob, and the panel shows it)
    rebind_progress: bool = False
    # True: the native object has response_basis() (ARAP's warm-start response to each
    # handle's affine motion): while a solve runs in a worker thread, each update shows the
    # last result moved by it to the handles' current transforms (solver.previews._basis_preview)
    response_basis: bool = False
    # extra solve keywords read from the scene on each frame: solve_args(obj, options, scene)
    # -> dict (a simulation's gravity, turned into the object's space, and its time step, the
    # scene's frame length)
    solve_args: Optional[Callable] = None
    # False: the method binds without handles (a simulation moves by its dynamics, a blend of
    # poses by its weights): the panel asks for none, and Solve From does not apply
    needs_handles: bool = True
    # a method driven by example poses (shape interpolation): the name of the add-on module
    # that reads them from Blender (poses_reader; shape_keys.py: poses(obj, options, rest) ->
    # P x n x 3 or None, the bind's `poses`; edit_input(obj, options, input) -> what the
    # native solve edits; signature(obj, options) -> what else of them the binding depends
    # on); its solve_args give the weights
    poses: Optional[str] = None
    # what a bind made that the artist should know, read from the native object once bound:
    # bind_summary(native) -> short text the status line ends with (Volume ARAP: how many
    # tetrahedra, or that the mesh bounds no volume and deforms as a surface)
    bind_summary: Optional[Callable] = None
    # True: on a mesh with shape keys, Add makes the deformer's modifier the first of the
    # stack (a blend of shape keys belongs where Blender applies them: above an Armature,
    # which then poses the blend)
    stack_first: bool = False


# What a method that solves with ARAP's solver declares (ARAP, Volume ARAP): its progress,
# the Stiffness group scaled by stiffness_scale, cold and warm solves, iterations with
# Newton's inner steps, the response basis for previews
_ARAP_SOLVER = dict(bind_progress=True, rebind_progress=True, maps=("stiffness",),
                    material_label="Stiffness", stiffness_option="stiffness_scale",
                    cold_solve={"warm_start": False}, warm_solve={"warm_start": True},
                    iterative=True, iteration_cap="max_iterations",
                    inner_iterations="cg_iterations", inner_when=("acceleration", "newton"),
                    response_basis=True)


def _arap_solver_options():
    """The options of ARAP's solver (its Newton steps and stopping test), one wording for
    ARAP and Volume ARAP, which solves with it."""
    return [
        # 1000: a guard against stalls, above the 88-268 steps an honest 1e-6 takes at
        # 692k vertices (a bake's frames and the refine solve stop at it)
        Option("max_iterations", "INT", 1000, "Max Iterations",
               "Most steps one solve takes: raise it when the panel says 'not "
               "converged', lower it to trade accuracy for speed",
               min=1, max=100000, advanced=True),
        Option("tolerance", "FLOAT", 1e-6, "Tolerance",
               "How settled the shape must be for a solve to stop (a step would change "
               "the energy by less than this fraction; Newton: and the energy left above "
               "the minimum is estimated below it): smaller is more exact and slower",
               min=0.0, max=1.0, advanced=True),
        # item order is stored in files: new items go last. Default: Newton (faster to
        # convergence and closer to the minimum, docs/methods/arap.md)
        Option("acceleration", "ENUM", "newton", "Solver",
               "How a solve steps towards the shape",
               items=(("anderson", "Accelerated",
                       "Many cheap local/global steps, sped up (Anderson acceleration): "
                       "long, slow bends can stop short of their final shape"),
                      ("none", "Basic",
                       "The paper's plain local/global steps: the slowest to settle; to "
                       "compare with other ARAP tools"),
                      ("newton", "Newton",
                       "Fewer, costlier steps that also settle long, slow bends (the "
                       "default): the quickest to the finished shape")),
               advanced=True),
        Option("cg_iterations", "INT", 12, "Newton Inner Steps",
               "Newton: inner (conjugate-gradient) steps per Newton step: more make each "
               "step costlier and closer to exact", min=1, max=100, advanced=True),
    ]


METHODS = [
    Method(
        id="ARAP",
        label="ARAP",
        native_class="ARAP",
        description="As-rigid-as-possible: keeps local shape, bends and twists naturally",
        icon="MOD_SIMPLEDEFORM",
        **_ARAP_SOLVER,
        options=[
            Option("energy", "ENUM", "spokes", "Keep Rigid",
                   "Which pieces of the surface the solve keeps rigid",
                   items=(("spokes", "Edge Rings",
                           "The edges around each vertex (the classic ARAP): fastest to bind "
                           "and solve"),
                          ("spokes_and_rims", "Edge Rings and Triangles",
                           "The edges of every triangle around each vertex too (spokes and "
                           "rims): steadier bends on coarse meshes or thin triangles, a "
                           "little slower"))),
            # default = the native default: negative cotangent weights make the energy
            # indefinite on real meshes (docs/methods/arap.md); item order is stored in files
            Option("weights", "ENUM", "clamped_cotangent", "Edge Weights",
                   "How much each edge counts in the rigidity",
                   items=(("cotangent", "Cotangent",
                           "From the triangles' angles, negative weights kept (the textbook "
                           "energy): on meshes with long thin triangles the bind can fail or "
                           "the solve stall"),
                          ("clamped_cotangent", "Cotangent, Clamped",
                           "From the triangles' angles, negative weights dropped (the "
                           "default): the same result on well-shaped meshes, safe on any "
                           "mesh"),
                          ("uniform", "Uniform",
                           "Every edge counts the same, whatever the triangles' shapes: a "
                           "rougher result that shifts with the mesh's density")),
                   advanced=True),
            *_arap_solver_options(),
            # 0 = the native default (automatic: a coarse level from 100,000 moving vertices on)
            Option("levels", "INT", 0, "Coarse Levels",
                   "The multi-scale solve: a simplified copy of the mesh per level (each "
                   "with a sixteenth of the vertices) first finds the overall shape, then "
                   "steers the full mesh's steps to it: 0 picks (one level from 100,000 "
                   "moving vertices on), 1 solves the mesh alone. The result is the same; big "
                   "meshes get there faster, at a slightly longer bind",
                   min=0, max=8, advanced=True),
            Option("stiffness_scale", "FLOAT", 10.0, "Painted Stiffness",
                   "How stiff the Stiffness group's vertices painted 1 are, against 1 for "
                   "the rest (paint in between blends): raise it to keep painted parts from "
                   "bending", min=0.001, max=1e6, kw=None, shown_with="material_group"),
        ],
        bind_summary=lambda native: _levels_summary(native),
    ),
    Method(
        id="LAPLACIAN",
        fit_check="stretch",
        label="Laplacian Edit",
        native_class="LaplacianEdit",
        description="Laplacian surface editing: one linear solve per update",
        icon="MOD_SMOOTH",
        bind_progress=True,
        rebind_progress=True,
        maps=("handle_weights",),
        options=[
            Option("weights", "ENUM", "cotangent", "Edge Weights",
                   "How much each neighbour counts in a vertex's detail",
                   items=(("cotangent", "Cotangent",
                           "From the triangles' angles (the default): detail that follows "
                           "the surface's true shape"),
                          ("uniform", "Uniform",
                           "Every neighbour counts the same: steadier on badly shaped "
                           "triangles, but the detail shifts with the mesh's density")),
                   advanced=True),
            Option("detail", "ENUM", "local_frame", "Detail",
                   "How the surface's detail (bumps, wrinkles) is carried along",
                   items=(("fixed", "Keep Direction",
                           "Detail keeps its rest direction: fastest, right for moves, but "
                           "bumps keep pointing the old way where the surface turns"),
                          ("membrane", "Flatten",
                           "No detail (a membrane): a smooth rubber sheet between the handles "
                           "and the Fixed group"),
                          ("local_frame", "Turn with Surface",
                           "Detail turns with the surface (the default): right for bends and "
                           "twists; each update solves once more per Detail Pass"))),
            Option("constraints", "ENUM", "hard", "Handle Fit",
                   "Whether the handles and the Fixed group are met exactly",
                   items=(("hard", "Exact",
                           "Handles and the Fixed group are met exactly (the default)"),
                          ("soft", "Approximate",
                           "Handles and the Fixed group pull like springs of strength Handle "
                           "Pull: the surface may fall short of them, for a smoother shape"))),
            Option("constraint_weight", "FLOAT", 1.0, "Handle Pull",
                   "How strongly soft handles pull to their targets: with Approximate fit "
                   "all handles and the Fixed group, else the handle vertices weighted below "
                   "1 (Soft handles)", min=1e-6, max=1e6),
            Option("tikhonov", "FLOAT", 0.0, "Rest Pull",
                   "Pulls every moving vertex back towards its rest position (0: off): a "
                   "little lets parts that no handle or Fixed vertex holds bind and stay "
                   "near rest; more stiffens the whole result", min=0.0, max=1e6,
                   advanced=True),
            Option("local_frame_iterations", "INT", 1, "Detail Passes",
                   "Turn with Surface: how often the detail is turned again to the reshaped "
                   "surface after the first solve; more follow big bends better, each costs "
                   "another solve", min=0, max=1000, advanced=True),
        ],
    ),
    Method(
        id="FALLOFF",
        fit_check="stretch",
        label="Falloff",
        native_class="Falloff",
        description="Attenuated handle displacement by distance from the handle",
        icon="SMOOTHCURVE",
        bind_progress=True,
        rebind_progress=True,
        maps=("handle_weights",),
        bind_args=lambda *a: falloff_args(*a),
        options=[
            # Straight Line by default, as Blender's proportional editing: with the automatic
            # range it stretched least on both demo scenes (arm-lift 11.5% RMS edge change
            # against 59% with Edge Steps and 53% Along Surface; armadillo-wave 15.7% against
            # 24% and 19%: docs/methods/falloff.md); the Python API's default too.
            Option("distance", "ENUM", "euclidean", "Distance",
                   "How the distance from a handle is measured",
                   items=(("hops", "Edge Steps",
                           "Edges counted from the handle: Range is a number of edges, so the "
                           "reach follows the mesh's density (dense parts fade sooner)"),
                          ("euclidean", "Straight Line",
                           "Straight through space, as proportional editing (the default): "
                           "Range is a length; also moves nearby parts the surface does not "
                           "connect (a hand resting on a leg)"),
                          ("geodesic", "Along Surface",
                           "Along the surface (heat method): Range is a length; smooth and "
                           "independent of the edge layout, slower to bind"),
                          ("dijkstra", "Along Edges",
                           "Shortest path along the edges: Range is a length; quick to bind, "
                           "a little longer than the surface distance where edges zigzag"))),
            Option("range_length", "FLOAT", 0.0, "Range",
                   "How far the handle's pull reaches, in the mesh's units. 0: automatic, "
                   "the distance from the handle to the Fixed group (the pull fades out "
                   "where the fixed part begins), or a quarter of the model's size without "
                   "one",
                   min=0.0, max=1e9, kw=None, subtype="DISTANCE",
                   shown_if=("distance", ("euclidean", "geodesic", "dijkstra"))),
            Option("range_hops", "INT", 0, "Range (Edges)",
                   "How many edges the handle's pull reaches. 0: automatic, the handle's "
                   "distance in edges to the Fixed group, or a quarter of the model's size "
                   "over the average edge length without one",
                   min=0, max=1000000, kw=None, shown_if=("distance", ("hops",))),
            Option("k", "FLOAT", 0.0, "Shape",
                   "The profile of the fade: 0 fades evenly; above 0 stays firm near the "
                   "handle and drops near the end of the range (rigid); below 0 drops fast "
                   "and lingers (elastic)", min=-100.0, max=100.0),
        ],
    ),
]

METHODS.append(Method(
    id="EMBEDDED",
    fit_check="handles",
    label="Embedded Deformation",
    native_class="EmbeddedDeformation",
    description="Deformation graph (Sumner et al. 2007): a few hundred nodes carry the "
                "shape, each an affine transformation kept close to a rotation; handles "
                "pull as soft constraints",
    icon="MOD_LATTICE",
    bind_progress=True,
    rebind_progress=True,
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
        Option("n_nodes", "INT", 200, "Nodes",
               "How many graph nodes carry the shape: more follow small parts and bend more "
               "locally; fewer give broader, smoother bends and solve faster",
               min=5, max=100000),
        Option("nodes", "ENUM", "surface", "Node Source",
               "Where the graph's nodes come from",
               items=(("surface", "Surface",
                       "Spread evenly over the surface (the paper's sampling): the most even "
                       "graph"),
                      ("vertices", "Vertices",
                       "Picked among the mesh's vertices (the paper's choice for an animated "
                       "mesh): the nodes sit on the mesh itself"))),
        Option("k", "INT", 4, "Nearest Nodes",
               "How many nodes move each vertex: more blend their motions more smoothly, "
               "fewer keep neighbouring parts apart", min=1, max=16, advanced=True),
        Option("distance", "ENUM", "euclidean", "Influence",
               "How a vertex's nearest nodes are found",
               items=(("euclidean", "Euclidean",
                       "Nearest in space (the paper's): a node can drag a part lying against "
                       "its own (a hand resting on a leg)"),
                      ("geodesic", "Geodesic",
                       "Nearest along the surface, so that a hand's node does not move the "
                       "leg it lies against (needs faces)"))),
        Option("cut_a", "GROUP", "", "Cut Side A",
               "With Cut Side B: no node near this vertex group moves the other, and no "
               "graph edge joins them (the paper's stroke between a hand and a leg)", kw=None),
        Option("cut_b", "GROUP", "", "Cut Side B",
               "With Cut Side A: the other side of the cut, moved by no node of Cut Side A",
               kw=None),
        Option("w_rot", "FLOAT", 1.0, "Rigidity",
               "How strongly each node keeps its piece rigid (no shear or stretch): raise it "
               "for stiffer parts", min=1e-6, max=1e6, advanced=True),
        Option("w_reg", "FLOAT", 10.0, "Smoothness",
               "How strongly neighbouring nodes agree: raise it for smoother, more even "
               "bends; lower lets the nodes move more on their own", min=1e-6, max=1e6,
               advanced=True),
        Option("w_con", "FLOAT", 2000.0, "Handle Pull",
               "How strongly the handles pull their vertices to the targets (handles are "
               "soft here): lower lets the shape lag behind the handles", min=1e-6, max=1e9,
               advanced=True),
        Option("max_iterations", "INT", 100, "Max Iterations",
               "Most Gauss-Newton steps one solve takes: raise it when the panel says 'not "
               "converged'", min=1, max=10000, advanced=True),
        Option("tolerance", "FLOAT", 1e-6, "Tolerance",
               "How settled the shape must be for a solve to stop: smaller is more exact "
               "and slower", min=1e-15, max=1.0, advanced=True),
        Option("show_graph", "BOOL", False, "Show Graph",
               "Draw the deformation graph's nodes and edges in the viewport",
               kw=None, bind_time=False),
    ],
))

METHODS.append(Method(
    id="EIGEN",
    fit_check="handles",
    label="Eigen Deformation",
    native_class="EigenDeformation",
    description="Eigen deformation (Dey, Ranjan & Wang): a smooth fit with the mesh's "
                "Laplace-Beltrami eigenvectors moves the part each handle drags (or the "
                "Region group), and the details are added back in local frames",
    icon="MOD_WAVE",
    preview={"preview": True},
    region_is_handle=True,
    region_kw={"region": "handles"},
    bind_progress=True,
    options=[
        Option("n_eigenvectors", "INT", 0, "Bend Shapes",
               "How many of the mesh's smooth shapes (eigenvectors) build the bend (0: "
               "automatic, 8, 50 or 300 from the region's size): fewer bend the mesh more "
               "broadly, more keep the bend near the region", min=0, max=2000),
        Option("refine", "INT", 300, "Detail Shapes",
               "When Bend Shapes is lower, how many shapes a second pass uses to rebuild the "
               "details (0: no second pass: a faster bind, coarser details)",
               min=0, max=2000, advanced=True),
        # item order is stored in files: new items go last
        Option("laplacian", "ENUM", "cotangent", "Shape Basis",
               "Which Laplacian's eigenvectors (smooth shapes) carry the deformation",
               items=(("cotangent", "Cotangent", "Cotangent weights with Voronoi areas: "
                                                 "binds fastest (the default)"),
                      ("belkin_sun_wang", "Belkin-Sun-Wang",
                       "The paper's mesh-Laplacian: a heat kernel over nearby vertices in "
                       "space; slower to bind, about the same shapes")),
               advanced=True),
    ],
))

METHODS.append(Method(
    id="LINEAR_RECONSTRUCTION",
    fit_check="stretch",
    label="Linear Reconstruction",
    native_class="LinearReconstruction",
    description="Linear reconstruction from discrete fundamental forms (Wang, Liu & Tong; "
                "Li): edge lengths and dihedral angles kept by one linear solve for positions "
                "and triangle frames",
    icon="MOD_TRIANGULATE",
    bind_progress=True,
    rebind_progress=True,
    maps=("material",),
    material_label="Material",
    options=[
        Option("softness", "FLOAT", 1.0, "Softness",
               "How much more easily the Material group's painted areas fold (0: as built, "
               "1: softest): paint where the surface should bend, an elbow. A gentle effect: "
               "this method keeps lengths and bends as a whole, and the paint gathers about a "
               "third more of a fold (for a sharp fold, ARAP with a Stiffness paint)",
               min=0.0, max=1.0, kw=None, shown_with="material_group"),
        Option("material_mode", "ENUM", "interpolate", "Material Paint",
               "How the Material group's weight paint becomes the material map",
               items=(("interpolate", "Interpolate",
                       "A smooth map through the painted vertices, as built at the handles and "
                       "the Fixed group: a few strokes are enough"),
                      ("smooth", "Smooth",
                       "The paint as painted, softened along the surface (Smoothing passes): "
                       "for detailed paint")),
               kw=None, shown_with="material_group"),
        Option("smooth_iterations", "INT", 10, "Smoothing",
               "Smooth: how many averaging passes soften the paint; more blur its edges",
               min=0, max=1000, kw=None, shown_with="material_group", advanced=True),
        Option("show_material", "BOOL", False, "Show Material",
               "Show the material map as the mesh's active colour attribute (Solid mode, "
               "Attribute colouring): grey as built, yellow softest",
               kw=None, bind_time=False, shown_with="material_group"),
        Option("w", "FLOAT", 1.0, "Bend Stiffness",
               "How strongly the surface keeps its bends against its edge lengths: raise "
               "it to keep creases and curvature, lower it to keep lengths and let it bend",
               min=1e-6, max=1e6, advanced=True),
        Option("orientation", "BOOL", False, "Turn Handle Faces",
               "A rotated handle target also turns the faces of its group (and the Fixed "
               "group's faces keep theirs): the surface leaves each handle at its angle"),
    ],
))


# Methods driven by a control object (their native kinds, solver.controls): no handles, no
# Region or Fixed group; the panel shows the control and its Make operator instead
METHODS.append(Method(
    id="LATTICE",
    label="Lattice",
    native_class="Lattice",
    description="Free-form deformation by a Lattice object: edit, key, hook or rig its "
                "points and the mesh inside follows",
    icon="MOD_LATTICE",
    needs_faces=False,
    options=[
        # default = the native default (and Blender's lattices' B-spline)
        Option("interpolation", "ENUM", "bspline", "Interpolation",
               "How the points around a vertex weigh on it",
               items=(("bspline", "B-Spline",
                       "Smooth: four points per axis around the vertex, as Blender's lattice "
                       "(the default); the border points are met exactly"),
                      ("linear", "Linear",
                       "The points of the vertex's cell, trilinear: follows the points "
                       "exactly, with creases at the cells' faces"),
                      ("bernstein", "Bernstein",
                       "Every point weighs on every vertex (Sederberg-Parry): the smoothest, "
                       "and the least local; at most 32 points per axis"))),
        Option("outside", "ENUM", "extend", "Outside",
               "What vertices outside the lattice's box do",
               items=(("extend", "Extend",
                       "They move as the nearest border cell continued (the default): an "
                       "affine edit of the lattice moves every vertex by it"),
                      ("clamp", "Clamp",
                       "They move as the box's nearest point, as Blender's Lattice modifier "
                       "with linear interpolation"),
                      ("still", "Fade Out",
                       "Their motion fades to none one cell beyond the box"))),
    ],
))

METHODS.append(Method(
    id="CAGE",
    label="Cage",
    native_class="Cage",
    description="Cage deformation with mean value coordinates: a closed mesh around the "
                "model moves it smoothly",
    icon="MOD_MESHDEFORM",
    needs_faces=False,
    options=[
        # default = the native default (mean value coordinates: linear precision)
        Option("coordinates", "ENUM", "mean_value", "Coordinates",
               "How each vertex is tied to the cage",
               items=(("mean_value", "Mean Value",
                       "To the cage's vertices (the default): the mesh follows the cage "
                       "closely, and stretching the cage stretches the mesh with it"),
                      ("green", "Green",
                       "To the cage's vertices and faces (Green coordinates): the mesh keeps "
                       "its shape, details scale instead of shearing when the cage is "
                       "stretched; a little slower, and the cage's faces must all face the "
                       "same way (Recalculate Normals)"))),
        Option("evaluation", "ENUM", "auto", "Evaluation",
               "Where the coordinates are computed",
               items=(("auto", "Auto",
                       "At every vertex, unless that would take more than 64 million "
                       "coefficients (a million vertices and a big cage): then on a grid "
                       "(the default)"),
                      ("exact", "Every Vertex",
                       "At every vertex: exact, but memory and each frame grow with the "
                       "vertices times the cage's size"),
                      ("grid", "Grid",
                       "At the corners of a grid's cells around the mesh, blended per "
                       "vertex: fast binds and frames at millions of vertices; the result "
                       "differs from the exact one by about a thousandth of the motion")),
               advanced=True),
        Option("grid_resolution", "INT", 64, "Grid Cells",
               "Grid evaluation: cells along the mesh's longest side; more follow the "
               "exact result closer (the difference falls with the square), and cost more "
               "memory and time", min=4, max=256, advanced=True,
               shown_if=("evaluation", ("auto", "grid"))),
        Option("weights", "ENUM", "double", "Precision",
               "How the coordinates are stored",
               items=(("double", "Double",
                       "Full precision (the default): 8 bytes per vertex and cage vertex"),
                      ("single", "Single",
                       "Half the memory, for millions of vertices: the motion to about 1e-7 "
                       "of itself")),
               advanced=True),
    ],
))


# appended last: the method's place in this list is what files store (enum_items)
METHODS.append(Method(
    id="SHEPARD",
    label="Shepard",
    native_class="Shepard",
    description="Shepard interpolation: each vertex blends the handles' motion (and the "
                "Fixed group's stillness), weighted by inverse distance",
    icon="MOD_WARP",
    bind_progress=True,
    maps=("handle_weights",),
    fit_check="stretch",
    options=[
        Option("interpolate", "ENUM", "transforms", "Blend",
               "What each vertex blends from the handles near it",
               items=(("transforms", "Handle Motions",
                       "Each handle's whole motion, turns included, applied to the vertex "
                       "(the default): smooth around the handles, a turned handle turns its "
                       "surroundings"),
                      ("displacements", "Displacements",
                       "The displacement of each handle's nearest vertex (the lecture's "
                       "formula): never beyond what the handles move, but flat plateaus "
                       "around each handle and no turning"))),
        Option("distance", "ENUM", "euclidean", "Distance",
               "How the distance from a handle or the Fixed group is measured",
               items=(("euclidean", "Straight Line",
                       "Straight through space (the default): quick; a part that touches "
                       "another in space is pulled with it (a hand resting on a leg)"),
                      ("geodesic", "Along Surface",
                       "Along the surface (heat method): parts near in space but far along "
                       "the surface do not pull each other; slower to bind"))),
        Option("power", "FLOAT", 2.0, "Power",
               "How strongly the nearest handle or the Fixed group wins: higher keeps each "
               "vertex with its nearest group (sharper transitions), lower blends more evenly",
               min=0.1, max=64.0),
        Option("neighbourhood", "ENUM", "all", "Blend Over",
               "Which handles (and the Fixed group) each vertex blends",
               items=(("all", "All Groups",
                       "Every handle and the Fixed group (the lecture's formula; the default)"),
                      ("nearest", "Nearest Groups",
                       "Its nearest ones (Groups), fading smoothly to none at the next one: "
                       "far handles leave a vertex alone"),
                      ("radius", "Within Radius",
                       "Those within Radius (at most Groups), fading to none at Radius: "
                       "vertices farther than that from every group stay still")),
               advanced=True),
        Option("k", "INT", 4, "Groups",
               "How many of the nearest handles (and the Fixed group) each vertex blends",
               min=1, max=1024, advanced=True, shown_if=("neighbourhood", ("nearest", "radius"))),
        Option("radius", "FLOAT", 0.0, "Radius",
               "Within Radius: how far a vertex looks for handles and the Fixed group, in the "
               "mesh's units (0: a quarter of the model's size)",
               min=0.0, max=1e9, subtype="DISTANCE", advanced=True,
               shown_if=("neighbourhood", ("radius",))),
    ],
))


METHODS.append(Method(
    id="SKINNING",
    label="Skinning",
    native_class="Skinning",
    description="Skinning by an Armature's bones with the vertex groups named after them: "
                "linear blend or dual quaternions",
    icon="MOD_ARMATURE",
    needs_faces=False,
    options=[
        Option("blend", "ENUM", "linear", "Blend",
               "How each vertex blends its bones' motions",
               items=(("linear", "Linear",
                       "Linear blend skinning (the default, as Blender's Armature modifier): "
                       "quick, but a limb twisted half a turn collapses at the joint"),
                      ("dual_quaternion", "Dual Quaternion",
                       "The bones' turns blended as dual quaternions (as the Armature "
                       "modifier's Preserve Volume): twisted and bent joints keep their "
                       "girth"))),
    ],
))


def shape_matching_solve_args(obj, opts, scene):
    """Gravity (the scene's, when the deformer's Gravity is on and the scene's is too) in the
    object's space, where the native object simulates; the frame's length in seconds."""
    import mathutils
    g = (0.0, 0.0, 0.0)
    if opts.use_gravity and scene.use_gravity:
        inv = obj.matrix_world.to_3x3().inverted_safe()
        g = tuple(inv @ mathutils.Vector(scene.gravity))
    fps = scene.render.fps / (scene.render.fps_base or 1.0)
    return {"gravity": g, "time_step": 1.0 / fps}


# A simulation (the native table's `dynamic`): each frame follows from the one before it,
# played from the scene's first frame (solver.simulation); handles are optional
METHODS.append(Method(
    id="SHAPE_MATCHING",
    label="Jiggle",
    native_class="ShapeMatching",
    description="Physically based jiggle and secondary motion (meshless shape matching): the "
                "mesh follows its input and handles with inertia, overshoots and settles",
    icon="PHYSICS",
    needs_faces=False,
    needs_handles=False,
    solve_args=shape_matching_solve_args,
    maps=("paint",),
    paint_keyword="attach_map",
    material_label="Hold",
    group_maps={"stiffness_group": "alpha_map", "damping_group": "damping_map",
                "squash_group": "beta_map"},
    options=[
        Option("alpha", "FLOAT", 0.3, "Stiffness",
               "How strongly each part is pulled back to its shape on each step (the paper's "
               "alpha): low jiggles slowly and far, 1 snaps back at once. Keyable",
               min=0.0, max=1.0, bind_time=False),
        Option("damping", "FLOAT", 4.0, "Damping",
               "How fast the jiggle dies out, per second (against the animation's own "
               "motion, so that moving parts are not dragged behind). Keyable",
               min=0.0, max=1000.0, bind_time=False),
        Option("mode", "ENUM", "linear", "Shape",
               "What each cluster of the mesh may do besides turning",
               items=(("rigid", "Rigid",
                       "Each cluster keeps its shape exactly: the stiffest wobble"),
                      ("linear", "Squash and Stretch",
                       "Clusters may also shear and stretch, keeping their volume (the "
                       "default): soft, fleshy motion"),
                      ("quadratic", "Bend and Twist",
                       "Clusters may also bend and twist: the softest, for long parts "
                       "(ears, tails)"))),
        Option("beta", "FLOAT", 0.3, "Squash Amount",
               "How far the clusters squash, stretch, bend or twist beyond turning (the "
               "paper's beta; Shape Rigid ignores it). Keyable",
               min=0.0, max=1.0, bind_time=False, shown_if=("mode", ("linear", "quadratic"))),
        Option("use_gravity", "BOOL", False, "Gravity",
               "Add the scene's gravity (off by default: an animated pose already hangs as it "
               "should, and gravity would sag it further)", kw=None, bind_time=False),
        Option("clusters", "ENUM", "cubes", "Clusters",
               "How the mesh is split into the overlapping pieces that keep their shape",
               items=(("cubes", "Local",
                       "Overlapping cubes of Cluster Size, split where the mesh is not "
                       "connected (the default): each region wobbles on its own"),
                      ("parts", "Whole Parts",
                       "One cluster per connected part: each part keeps its shape as a whole "
                       "(the paper's basic method)"))),
        Option("cluster_size", "FLOAT", 0.0, "Cluster Size",
               "Edge of the cubes (0: a quarter of the mesh's size): smaller clusters let "
               "smaller regions wobble and make long parts floppier",
               min=0.0, max=1e9, subtype="DISTANCE", shown_if=("clusters", ("cubes",)),
               advanced=True),
        Option("stiffness_group", "GROUP", "", "Stiffness Paint",
               "A vertex group whose weights scale the Stiffness per vertex (1 where it has "
               "none): paint softer flesh low", kw=None, advanced=True),
        Option("damping_group", "GROUP", "", "Damping Paint",
               "A vertex group whose weights scale the Damping per vertex (1 where it has "
               "none): paint parts that should swing longer low", kw=None, advanced=True),
        Option("squash_group", "GROUP", "", "Squash Paint",
               "A vertex group whose weights scale the Squash Amount per vertex (1 where it "
               "has none)", kw=None, advanced=True),
        Option("falloff", "FLOAT", 0.0, "Blend Distance",
               "How far from what follows the rig (the Fixed group, outside the Region, the "
               "handles) the jiggle fades in (0: half the depth of the region, and with Local "
               "clusters at most half the Cluster Size): no crease where the two meet. Paint "
               "the Hold group to hold more", min=0.0, max=1e9,
               subtype="DISTANCE", advanced=True),
        Option("substeps", "INT", 2, "Substeps",
               "Integration steps per frame: more make the same Stiffness stiffer and the "
               "motion smoother", min=1, max=64, advanced=True),
        Option("integrator", "ENUM", "semi_implicit_euler", "Integrator",
               "How each step moves the points",
               items=(("semi_implicit_euler", "Semi-Implicit Euler",
                       "Velocity first, then position (the paper's scheme, the default): "
                       "stable for any Stiffness, keeps the jiggle's energy"),
                      ("explicit_euler", "Explicit Euler",
                       "Position from the old velocity (the lecture's first integrator): "
                       "gains energy and blows up; for comparison only"),
                      ("implicit_euler", "Implicit Euler",
                       "Backward Euler: stable and strongly damped, the jiggle dies fast"),
                      ("rk4", "Runge-Kutta 4",
                       "Four evaluations per step: accurate, loses a little energy")),
               advanced=True),
        Option("plastic_creep", "FLOAT", 0.0, "Plasticity",
               "How fast a strongly deformed region keeps its new shape, per second (0: "
               "always springs back)", min=0.0, max=1000.0, bind_time=False, advanced=True),
        Option("plastic_yield", "FLOAT", 0.1, "Yield",
               "How far a region must deform before Plasticity keeps any of it",
               min=0.0, max=100.0, bind_time=False, advanced=True),
        Option("plastic_max", "FLOAT", 1.0, "Max Plastic",
               "The most Plasticity may keep of a deformation", min=0.0, max=100.0,
               bind_time=False, advanced=True),
    ],
))


METHODS.append(Method(
    id="SHAPE_BLEND",
    label="Shape Blend",
    native_class="ShapeInterpolation",
    description="Blends the mesh's shape keys keeping the shape: parts turn and stretch "
                "between the keys instead of sliding straight through (shape interpolation)",
    icon="SHAPEKEY_DATA",
    needs_handles=False,
    poses="shape_keys",
    stack_first=True,
    solve_args=lambda obj, opts, scene: poses_reader(get("SHAPE_BLEND")).solve_args(obj, opts,
                                                                                  scene),
    options=[
        Option("key_names", "STRING", "", "Shape Keys",
               "The shape keys this deformer blends, by name, separated by commas (empty: "
               "every key but the Basis). Their sliders, keyframes and drivers set the blend; "
               "the other keys stay Blender's straight blend", kw=None),
        Option("rotations", "ENUM", "consistent", "Turns",
               "How far a part may turn between the Basis and a key",
               items=(("consistent", "Any Angle",
                       "Turns beyond half a turn, and twists of whole turns, go the way the "
                       "key took them, judged across the mesh (the default)"),
                      ("principal", "Shortest Way",
                       "Each triangle turns the shortest way: a part turned by more than half "
                       "a turn unwinds the other way, a whole-turn twist does not turn at "
                       "all; for comparison")),
               advanced=True),
        Option("stretches", "ENUM", "linear", "Stretch Blend",
               "How each triangle's stretch is blended between the Basis and a key",
               items=(("linear", "Straight",
                       "Stretch blended in proportion (the default): exact where a limb "
                       "bends, its inside squeezing and outside stretching with the angle"),
                      ("log", "Area Keeping",
                       "Stretch blended so that a shear keeps each triangle's area: better "
                       "volume where a wide body twists; the blend takes about twice as "
                       "long")),
               advanced=True),
        Option("refine", "INT", 0, "Refine Passes",
               "Passes that turn each triangle to fit the blended shape, keeping its blended "
               "stretch: they even out big twists (a whole-turn twist thins in the middle "
               "without them); each pass takes about twice the blend's time",
               min=0, max=100, advanced=True),
        Option("edge_weights", "ENUM", "clamped_cotangent", "Edge Weights",
               "How much each edge counts when the blended triangles are stitched together",
               items=(("clamped_cotangent", "Cotangent, Clamped",
                       "From the triangles' angles, negative weights dropped (the default): "
                       "safe on any mesh"),
                      ("cotangent", "Cotangent",
                       "From the triangles' angles, negative weights kept: a mesh with many "
                       "long thin triangles can fail to bind"),
                      ("uniform", "Uniform",
                       "Every edge counts the same, whatever the triangles' shapes")),
               advanced=True),
    ],
))

def _levels_summary(native):
    """ARAP's bind, in the status line: the coarse levels of its multi-scale solve, if any
    (from 100,000 moving vertices on by default: the artist sees why the bind took longer)."""
    stats = getattr(native, "stats", None)
    coarse = stats.get("coarse_vertices", ()) if isinstance(stats, dict) else ()
    if not coarse:
        return ""
    return "coarse level%s of %s vertices" % (
        "s" if len(coarse) > 1 else "", " and ".join("{:,}".format(n) for n in coarse))


def _volume_summary(native):
    """Volume ARAP's bind, in the status line: the solid's tetrahedra, or why (part of) the
    mesh bounds no volume and deforms as a surface (the native volume_note)."""
    n, note = getattr(native, "n_tetrahedra", None), getattr(native, "volume_note", "")
    if n is None:   # the tests' stand-in module (tests/blender/mock)
        return ""
    if n == 0:
        why = ("its closed surface crosses itself" if "intersects" in note
               else "it is not closed (a hole, or an edge shared by more than two faces)"
               if "no closed part" in note else note.replace("no volume: ", ""))
        return "no volume: deformed as a surface (%s)" % why
    stats = getattr(native, "stats", None)
    if isinstance(stats, dict) and stats.get("embedded"):
        return "carried by a coarse solid of {:,} points, {:,} tetrahedra".format(
            stats.get("n_points", 0), n)
    text = "%d tetrahedra inside" % n
    coarse = stats.get("coarse_points", 0) if isinstance(stats, dict) else 0
    if coarse:
        text += ", coarse level of {:,} points".format(coarse)
    return text + ("; parts with holes deform as surfaces" if note else "")


METHODS.append(Method(
    id="VOLUME_ARAP",
    label="Volume ARAP",
    native_class="VolumetricARAP",
    description="As-rigid-as-possible on the solid inside the mesh (tetrahedra): bent and "
                "twisted limbs keep their volume instead of thinning or bulging",
    icon="MESH_ICOSPHERE",
    **_ARAP_SOLVER,
    bind_summary=lambda native: _volume_summary(native),
    options=[
        Option("quality", "FLOAT", 1.5, "Tetrahedra Shape",
               "How well-shaped the solid's tetrahedra must be (the radius of each one's "
               "sphere against its shortest edge): lower adds more inner points, binds slower "
               "and bends more evenly", min=1.1, max=10.0, advanced=True),
        *_arap_solver_options(),
        # 0 = the native default (automatic: a coarse level from 10,000 points on)
        Option("levels", "INT", 0, "Coarse Level",
               "The multi-scale solve: a simplified copy of the solid (a sixteenth of the "
               "surface, its own tetrahedra) first finds the overall shape when the "
               "deformer starts over, and the full solid starts from it: 0 picks (from "
               "10,000 points inside and on the surface), 1 solves the solid alone, 2 "
               "always adds the level. The result is the same for usual edits (a half turn "
               "can settle into another twist) and arrives several times faster, at a "
               "slightly longer bind", min=0, max=2, advanced=True),
        # 0 = the native default (automatic: a coarse solid from 250,000 closed vertices on)
        Option("embed", "INT", 0, "Coarse Solid",
               "What carries the surface: 1 tetrahedralizes the mesh itself, 2 a coarse copy "
               "of its solid (a sixteenth of the surface, its own tetrahedra) that the mesh "
               "rides on, each vertex at its place in the coarse tetrahedra, handles and fixed "
               "parts exact: far faster and smaller binds and solves, the bend of the coarse "
               "solid with the mesh's details on it. 0 picks 2 from 250,000 vertices when "
               "every part of the mesh is closed (the mesh's own solid would need over 3 GB)",
               min=0, max=2, advanced=True),
        Option("stiffness_scale", "FLOAT", 10.0, "Painted Stiffness",
               "How stiff the Stiffness group's vertices painted 1 are, against 1 for the "
               "rest (the inside takes the stiffness of the surface around it)",
               min=0.001, max=1e6, kw=None, shown_with="material_group"),
    ],
))

BY_ID = {m.id: m for m in METHODS}


def _check_registry():
    """Every field that names an option names one of the method's options; every option and
    enum item has a label and a description (the artist reads them)."""
    for m in METHODS:
        names = {o.name for o in m.options}
        for o in m.options:
            if not (o.label and o.description.strip()):
                raise ValueError("%s.%s needs a label and a description" % (m.id, o.name))
            if o.type == "ENUM":
                if o.default not in {i[0] for i in o.items}:
                    raise ValueError("%s.%s: default %r is not an item" % (m.id, o.name,
                                                                          o.default))
                for item in o.items:
                    if len(item) != 3 or not (item[1] and item[2].strip()):
                        raise ValueError("%s.%s: item %r needs a name and a description"
                                         % (m.id, o.name, item[0]))
        for field_name in ("stiffness_option", "iteration_cap", "inner_iterations"):
            ref = getattr(m, field_name)
            if ref is not None and ref not in names:
                raise ValueError("%s.%s names %r, which is not one of its options"
                                 % (m.id, field_name, ref))
        if ("stiffness" in m.maps) != (m.stiffness_option is not None):
            raise ValueError("%s: a 'stiffness' map needs a stiffness_option" % m.id)
        if ("paint" in m.maps) != (m.paint_keyword is not None):
            raise ValueError("%s: a 'paint' map needs a paint_keyword" % m.id)
        groups = {o.name for o in m.options if o.type == "GROUP"}
        if any(o.type == "GROUP" and o.kw is not None for o in m.options):
            raise ValueError("%s: GROUP options are read by the add-on (kw=None)" % m.id)
        if ("cut" in m.maps) != (m.cut_options is not None) or (
                m.cut_options is not None and (len(m.cut_options) != 2
                                               or not set(m.cut_options) <= groups)):
            raise ValueError("%s: a 'cut' map needs cut_options naming two GROUP options"
                             % m.id)
        if not set(m.group_maps) <= groups:
            raise ValueError("%s: group_maps must name GROUP options" % m.id)
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


def poses_reader(method):
    """The add-on module that reads method's example poses (Method.poses), or None."""
    if method.poses is None:
        return None
    import importlib
    return importlib.import_module("." + method.poses, __package__)


def enum_items():
    return [(m.id, m.label, m.description, m.icon, i) for i, m in enumerate(METHODS)]


def options_attr(method_id):
    """Name of the PointerProperty on a deformer holding this method's options."""
    return "options_" + method_id.lower()


def falloff_args(opts, rest, kw, mesh):
    """Falloff's reach from the add-on's options: Range (a length) or Range (Edges), the one
    the distance kind uses, when set (reach='range'); at 0 (the default) nothing, so the
    native defaults apply, as from Python: each handle's distance to the Fixed group
    (reach='fixed': the pull fades out exactly where the fixed part begins), else a quarter
    of the bounding-box diagonal (dk_falloff.h, DK_FALLOFF_AUTO_RANGE)."""
    hops = opts.distance == "hops"
    given = opts.range_hops if hops else opts.range_length
    if given > 0:
        return {"range": float(given), "reach": "range"}
    return {}


def constructor_kwargs(method, opts):
    """Constructor keywords from an options PropertyGroup (only the ones mapped to the API)."""
    kw = {}
    for o in method.options:
        if o.keyword is not None and o.bind_time:
            kw[o.keyword] = getattr(opts, o.name)
    return kw


def bind_kwargs(method, opts, rest, constraints, mesh):
    """Every constructor keyword the add-on's options give (constructor_kwargs, plus the
    method's bind_args computed from the rest positions, the constraint keywords and the
    native Mesh): what a bind passes, and what tests pass to compare with the API."""
    kw = constructor_kwargs(method, opts)
    if method.bind_args is not None:
        kw.update(method.bind_args(opts, rest, constraints, mesh))
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

"""Settings stored in the .blend: Object.deformkit -> deformers -> handles (+ method options).

Only names and values are stored (vertex-group names, a target object pointer, matrices);
solver state lives in the solver package and is rebuilt on demand.
"""

import re

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, PointerProperty, StringProperty)

from . import compat, geonodes, methods
from .solver import cache, identity

IDENTITY16 = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _touch(self, context):
    """Any settings change: mark solver inputs dirty (the handler re-checks and re-solves)."""
    cache.mark_settings_changed()


# A deformer's name as the add-on gives it: "DeformKit <method label>", with ".NNN" when taken
AUTO_NAME = "DeformKit %s"
_AUTO_NAME_RE = re.compile(r"DeformKit (.+?)(\.\d{3})?")


def _auto_label(name):
    """The method label in a name the add-on gave, or None for a name the user typed."""
    m = _AUTO_NAME_RE.fullmatch(name)
    if m is None or m.group(1) not in {x.label for x in methods.METHODS}:
        return None
    return m.group(1)


def unique_name(dks, label, skip=None):
    """AUTO_NAME for `label`, with the first free ".NNN" when another deformer of `dks` (but
    `skip`) has it."""
    names = {x.name for x in dks.deformers if skip is None or x.uid != skip.uid}
    name, i = AUTO_NAME % label, 1
    while name in names:
        i += 1
        name = "%s.%03d" % (AUTO_NAME % label, i)
    return name


def _method_changed(self, context):
    """The method switched: re-solve, and a name the add-on gave follows the new method
    ("DeformKit ARAP" becomes "DeformKit Laplacian Edit"), its modifier too when it still
    carries the deformer's name; a name the user typed stays."""
    _touch(self, context)
    label = methods.get(self.method).label
    if _auto_label(self.name) in (None, label):
        return
    old = self.name
    self.name = unique_name(self.id_data.deformkit, label, skip=self)
    mod = geonodes.find_modifier(self.id_data, self)
    if mod is not None and mod.name == old:
        mod.name = self.name


def _control_poll(self, ob):
    """The objects the deformer's method can take as its control: a Lattice object for a
    lattice, any other mesh for a cage (solver.controls: the collector of its kinds)."""
    from .solver import controls
    if controls.uses_handles(self):
        return False
    return ob.type == controls.of(self).OBJECT_TYPE and ob.name != self.id_data.name


class DeformKitHandle(bpy.types.PropertyGroup):
    # name (from PropertyGroup) is the label shown in the list
    vertex_group: StringProperty(name="Vertex Group", description="Vertices moved by this handle",
                                 update=_touch)
    target: PointerProperty(name="Target", type=bpy.types.Object, update=_touch,
                            description="Object (or armature) whose motion since bind moves the "
                                        "handle's vertices, like a Hook")
    subtarget: StringProperty(name="Bone", description="Bone of an armature target", update=_touch)
    use_weights: BoolProperty(name="Soft (use weights)", default=False, update=_touch,
                              description="Use the vertex group's weights as soft-handle weights "
                                          "(methods that support it)")
    bind_matrix: FloatVectorProperty(name="Bind Matrix", size=16, default=IDENTITY16,
                                     description="inverse(target world) @ object world at bind")
    is_bound: BoolProperty(name="Bound", default=False)
    rig_matrix: FloatVectorProperty(name="Rig Matrix", size=16, default=(0.0,) * 16,
                                    description="How the rig moved the target's bone at bind "
                                                "(object space), all 0 when the target rides "
                                                "no bone of a rig that deforms the input")
    follow: EnumProperty(
        name="Edit", default="POSE", update=_touch,
        items=(("POSE", "Follows the Pose",
                "The handle's edit turns with its vertices as the animation (an Armature, "
                "shape keys) turns them: a correction keyed once stays on its side of a "
                "bending limb"),
               ("WORLD", "Stays in Place",
                "The handle's vertices go where the target puts them, wherever the animation "
                "carries them: for a handle that must reach an absolute place (a hand on a "
                "table)")),
        description="What the handle's edit does where modifiers or shape keys above the "
                    "deformer move its vertices")
    pose_matrix: FloatVectorProperty(name="Pose Matrix", size=16, default=(0.0,) * 16,
                                     description="The rigid fit of the handle's vertices from "
                                                 "the rest to the deformer's input at bind, "
                                                 "all 0 before it is known")


def _make_options_group(method):
    ann = {}
    for o in method.options:
        common = dict(name=o.label or o.name, description=o.description, update=_touch)
        if o.type == "ENUM":
            ann[o.name] = EnumProperty(items=list(o.items), default=o.default, **common)
        elif o.type == "INT":
            kw = {}
            if o.min is not None:
                kw["min"] = int(o.min)
            if o.max is not None:
                kw["max"] = int(o.max)
            ann[o.name] = IntProperty(default=o.default, **kw, **common)
        elif o.type == "FLOAT":
            kw = {}
            if o.min is not None:
                kw["min"] = o.min
            if o.max is not None:
                kw["max"] = o.max
            prec = 7 if abs(o.default) and abs(o.default) < 1e-3 else 3
            ann[o.name] = FloatProperty(default=o.default, precision=prec, subtype=o.subtype,
                                        **kw, **common)
        elif o.type == "BOOL":
            ann[o.name] = BoolProperty(default=o.default, **common)
        elif o.type in ("GROUP", "STRING"):
            ann[o.name] = StringProperty(default=o.default, **common)
        else:
            raise ValueError("unknown option type %r" % o.type)
    return type("DeformKitOptions_" + method.id, (bpy.types.PropertyGroup,),
                {"__annotations__": ann})


OPTION_CLASSES = [_make_options_group(m) for m in methods.METHODS]


_deformer_ann = {
    "uid": StringProperty(name="UID", description="Stable id: attribute and cache key"),
    "method": EnumProperty(name="Method", items=methods.enum_items(), update=_method_changed),
    "roi_group": StringProperty(name="Region", update=_touch,
                                description="Vertex group: only these vertices move (empty: all)"),
    "fixed_group": StringProperty(name="Fixed", update=_touch,
                                  description="Vertex group: these vertices stay at rest"),
    "material_group": StringProperty(name="Material", update=_touch,
                                     description="Weight-painted vertex group: where ARAP is "
                                                 "stiffer (its Stiffness group), where Linear "
                                                 "Reconstruction folds more easily (its "
                                                 "Material group)"),
    "handles": CollectionProperty(type=DeformKitHandle),
    # a method driven by a control object (solver.controls: a lattice, a cage): the object,
    # and what Bind kept of it (solver.control_objects)
    "control_object": PointerProperty(
        name="Control", type=bpy.types.Object, poll=_control_poll, update=_touch,
        description="The lattice or cage whose points move the mesh: edit, key, hook or rig "
                    "it, and the mesh follows"),
    "control_bind": StringProperty(name="Control at Bind",
                                   description="The control's rest, taken at Bind (float64, "
                                               "base64)"),
    "control_bound_object": PointerProperty(name="Bound Control", type=bpy.types.Object,
                                            description="The control object Bind took the "
                                                        "rest from"),
    "active_handle": IntProperty(name="Active Handle", default=0),
    "bound": BoolProperty(name="Bound", default=False),
    # what the method deforms when something above moves its input (solver.solving._plan_solve)
    "solve_from": EnumProperty(
        name="Solve From", default="POSE", update=_touch,
        items=(("POSE", "Input Pose",
                "Edit the pose the modifiers above give: with the handles where they put "
                "them the result is that pose (methods that cannot edit a pose add their "
                "offset, solved on the rest, to it)"),
               ("REST", "Rest Shape",
                "Solve from the rest shape with the handles where the modifiers above put "
                "them, plus their edits: the method replaces the rig's deformation between "
                "the handles (put the parts the rig moves in handles on their bones; Fixed "
                "vertices stay at rest)")),
        description="What the deformer solves from when modifiers or shape keys above it move "
                    "its input"),
    # the frame whose handle placements and pose Bind takes as the rest (solver.rest_frame)
    "rest_frame_from": EnumProperty(
        name="Rest Frame", default="START",
        items=(("START", "Scene Start",
                "Bind takes the handles' placement and the pose on the scene's first frame as "
                "the rest, whichever frame is shown: a keyed correction is never inverted"),
               ("FRAME", "Frame", "Bind takes them on the frame given below"),
               ("CURRENT", "Current Frame", "Bind takes them on the frame shown")),
        description="The frame Bind takes the rest from: where the handles are placed and how "
                    "the animation poses the mesh there, the state the edits are made from"),
    "rest_frame": IntProperty(name="Frame", default=1,
                              description="Bind's rest frame (Rest Frame: Frame)"),
    "bind_n_vertices": IntProperty(name="Vertices at Bind", default=0),
    "bind_n_faces": IntProperty(name="Faces at Bind", default=0),
    # methods.Method.bind_summary's text at the last Bind (empty for the other methods)
    "bind_summary": StringProperty(name="Bind Summary", default=""),
    # solver.topology_fingerprint of the mesh at bind (connectivity and vertex order): a
    # short string, so a file saved with it opens (and renders) without the add-on
    "bind_topology": StringProperty(name="Topology at Bind",
                                    description="Fingerprint of the mesh's faces and vertex "
                                                "order at bind"),
    # the object that holds this uid (solver.ensure_own_uid): a copy (Shift+D, Alt+D) still
    # names the original and gets a uid, attribute and cache of its own
    "owner": StringProperty(name="Owner", description="The object this deformer's id "
                                                      "belongs to"),
    # a simulation's frame key (solver.simulation.frame_key, hex) whose result the offset
    # attribute holds, or "": that frame shows it again after a reload, when the frames
    # played before it are no longer kept
    "sim_frame_key": StringProperty(name="Simulated Frame", default=""),
    "status": StringProperty(name="Status"),
    "status_is_error": BoolProperty(default=False),
    "status_overlap": StringProperty(name="Overlapping Groups",
                                     description="The two vertex groups of an overlap error, "
                                                 "tab-separated"),
    "last_solve_ms": FloatProperty(name="Last Solve (ms)", default=0.0),
    "show_expanded": BoolProperty(default=True),
    "modifier_name": StringProperty(name="Modifier",
                                    description="Name of the deformer's Geometry Nodes "
                                                "modifier (found again by it if its Attribute "
                                                "input is edited)"),
    # the bake that replaced the live result (bake.py): what, where, which frames
    "bake_kind": EnumProperty(name="Baked", default="NONE", items=(
        ("NONE", "Not Baked", "The deformer's live result shows"),
        ("PC2", "Point Cache", "A Mesh Cache modifier plays a PC2 file in its place"),
        ("SHAPE_KEYS", "Shape Keys", "One keyed shape key per frame plays in its place"))),
    "bake_target": StringProperty(name="Bake Target",
                                  description="The Mesh Cache modifier's name, or the shape "
                                              "keys' name prefix"),
    "bake_file": StringProperty(name="Cache File", subtype="FILE_PATH",
                                options=compat.BLEND_RELATIVE_PATH,
                                description="Where Bake to Point Cache writes (empty: "
                                            "//<object>_<deformer>.pc2 next to the .blend)"),
    "bake_start": IntProperty(name="Baked From", default=0),
    "bake_end": IntProperty(name="Baked To", default=0),
    # the options box's Advanced section (ui.draw_options): open or collapsed
    "show_advanced": BoolProperty(name="Advanced", default=False,
                                  description="Show the expert options: tolerances, iteration "
                                              "caps, solver internals, energy weights"),
}
for _m, _cls in zip(methods.METHODS, OPTION_CLASSES):
    _deformer_ann[methods.options_attr(_m.id)] = PointerProperty(type=_cls)

DeformKitDeformer = type("DeformKitDeformer", (bpy.types.PropertyGroup,),
                         {"__annotations__": _deformer_ann})


def _deformer_attribute(self):
    return "dk_%s_offset" % self.uid


def _deformer_input_attribute(self):
    return "dk_%s_input" % self.uid


def _deformer_options(self):
    return getattr(self, methods.options_attr(self.method))


DeformKitDeformer.attribute_name = property(_deformer_attribute)
DeformKitDeformer.input_attribute_name = property(_deformer_input_attribute)
DeformKitDeformer.options = property(_deformer_options)


class DeformKitObject(bpy.types.PropertyGroup):
    deformers: CollectionProperty(type=DeformKitDeformer)
    active_index: IntProperty(name="Active Deformer", default=0)


CLASSES = OPTION_CLASSES + [DeformKitHandle, DeformKitDeformer, DeformKitObject]


def new_deformer(obj, method_id):
    dks = obj.deformkit
    d = dks.deformers.add()
    d.uid = identity.new_uid()
    d.owner = obj.name
    d.method = method_id
    d.name = unique_name(dks, methods.get(method_id).label, skip=d)
    dks.active_index = len(dks.deformers) - 1
    return d


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Object.deformkit = PointerProperty(type=DeformKitObject)


def unregister():
    del bpy.types.Object.deformkit
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)

"""Screenshot of the Modifiers tab with a DeformKit deformer, drawn with no Python errors.

  python3 tests/blender/screenshot_ui.py [BUILD_PYTHON_DIR]
runs `xvfb-run -a blender --factory-startup --python <this file>`, which saves
tests/blender/output/modifiers_tab.png (the whole window; the biggest area shows the
Modifiers tab), and fails if Blender
printed any Python error (a panel that fails to draw prints a traceback, not an exception).
"""
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "output")
PNG = os.path.join(OUT, "modifiers_tab.png")
# the second deformer (the registry's last method) made active, its options drawn with the
# Advanced section open, and its error status wrapped over lines
PNG2 = os.path.join(OUT, "modifiers_tab_last_method.png")
# a 3D viewport with a bound embedded deformation and Show Graph on (overlay.py), in a second
# Blender run (DEFORMKIT_SHOT=graph): the graph's nodes and edges drawn over the mesh
PNG3 = os.path.join(OUT, "viewport_show_graph.png")
# the panel in each state an artist meets (DEFORMKIT_SHOT=states, a third run): one image
# each, kept in docs/images after being looked at
STATES = ("unbound", "bound", "bound_warning", "rebinding", "baked", "overlap_error", "handle_target",
          "sidebar", "lattice", "cage", "cage_view", "skinning_view", "jiggle", "shape_blend",
          "volume_arap", "arap_levels")
STATE_PNGS = [os.path.join(OUT, "panel_%s.png" % s) for s in STATES]

try:
    import bpy  # noqa: F401
    IN_BLENDER = True
except ImportError:
    IN_BLENDER = False


def launch():
    env = dict(os.environ)
    if len(sys.argv) > 1:
        env["PYTHONPATH"] = sys.argv[1]
    os.makedirs(OUT, exist_ok=True)
    for p in (PNG, PNG2, PNG3) + tuple(STATE_PNGS):
        if os.path.exists(p):
            os.remove(p)
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", "blender", "--factory-startup",
           "--python", os.path.abspath(__file__)]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    r2 = subprocess.run(cmd, env=dict(env, DEFORMKIT_SHOT="graph"), capture_output=True,
                        text=True, timeout=300)
    # the states run clicks the sidebar's tab with simulated events
    cmd3 = cmd[:-2] + ["--enable-event-simulate"] + cmd[-2:]
    r3 = subprocess.run(cmd3, env=dict(env, DEFORMKIT_SHOT="states"), capture_output=True,
                        text=True, timeout=300)
    log = (r.stdout + r.stderr + "\n--- Show Graph run ---\n" + r2.stdout + r2.stderr +
           "\n--- panel states run ---\n" + r3.stdout + r3.stderr)
    with open(os.path.join(OUT, "screenshot_ui.log"), "w") as f:
        f.write(log)
    bad = [ln for ln in log.splitlines()
           if "Traceback" in ln or "Error: Python" in ln or "Error" in ln and "rna_uiItem" in ln
           or ln.startswith(("AttributeError", "TypeError", "KeyError", "NameError", "ValueError",
                             "RuntimeError"))]
    ok = (r.returncode == 0 and r2.returncode == 0 and r3.returncode == 0 and not bad and
          all(os.path.exists(p) for p in (PNG, PNG2, PNG3) + tuple(STATE_PNGS)))
    print(log[-3000:])
    for ln in bad:
        print("PYTHON ERROR IN CONSOLE:", ln)
    print("screenshot_ui: %d passed, %d failed (%s)" % (int(ok), int(not ok), PNG))
    sys.exit(0 if ok else 1)


def in_blender():
    sys.path.insert(0, HERE)
    import _setup as S
    import bpy
    from mathutils import Euler
    R = S.Results("screenshot_ui")
    MID = next((m.id for m in S.methods.METHODS if S.native.has_class(m.native_class)), "ARAP")

    def setup():
        S.reset_scene()
        with bpy.context.temp_override(**S.ui_context()):
            obj, d, e, fixed, handle = S.grid_setup(MID)
            S.group(obj, "tip2", [5, 6, 17, 18])
            e2 = S.empty("Tip 2", (0.0, -0.4, 0.0))
            bpy.ops.deformkit.add_handle(vertex_group="tip2", target=e2.name)
            d.handles[0].name = "Tip"
            d.handles[1].name = "Middle"
            obj.vertex_groups.new(name="stiff")
            d.material_group = "stiff"
            bpy.ops.deformkit.bind()
            e.location.z += 0.4
            bpy.context.view_layer.update()
            # a second deformer in the list, showing an error status
            bpy.ops.deformkit.add_deformer(method=S.methods.METHODS[-1].id)
            d2 = obj.deformkit.deformers[1]
            try:
                bpy.ops.deformkit.bind()
            except RuntimeError:
                pass
            obj.deformkit.active_index = 0
            S.geonodes.find_modifier(obj, d).show_expanded = False
            S.geonodes.find_modifier(obj, d2).show_expanded = False
            win = bpy.context.window_manager.windows[0]
            # turn the biggest area into a Properties editor on the Modifiers tab
            area = max(win.screen.areas, key=lambda a: a.width * a.height)
            area.type = "PROPERTIES"
            R.check("deformer bound", d.bound and not d.status_is_error, d.status)

    def window_shot(win, area, path):
        """Redraws, then saves the whole window (screen.screenshot_area gives a 1x1 image
        under Xvfb; the window shot works)."""
        with bpy.context.temp_override(window=win, area=area, screen=win.screen):
            bpy.ops.wm.redraw_timer(type="DRAW_WIN_SWAP", iterations=2)
        with bpy.context.temp_override(window=win, screen=win.screen):
            bpy.ops.screen.screenshot(filepath=path)

    def finish():
        print("%s: %d passed, %d failed" % (R.name, R.passed, R.failed))
        sys.stdout.flush()
        os._exit(1 if R.failed or not R.passed else 0)

    def shoot():
        try:
            win = bpy.context.window_manager.windows[0]
            area = max(win.screen.areas, key=lambda a: a.width * a.height)
            area.spaces.active.context = "MODIFIER"
            window_shot(win, area, PNG)
            R.check("screenshot saved", os.path.exists(PNG))
            obj = bpy.context.view_layer.objects.active
            obj.deformkit.active_index = 1
            d2 = obj.deformkit.deformers[1]
            opts = d2.options
            for o in S.methods.get(d2.method).options:
                if o.type == "GROUP":
                    setattr(opts, o.name, "fixed")
            d2.show_advanced = True
            d2.material_group = "stiff"
            S.solver.set_status(d2, "a long error wraps over the panel's lines: " + " ".join(
                "word%d" % i for i in range(60)), True)
            window_shot(win, area, PNG2)
            R.check("second screenshot saved", os.path.exists(PNG2))
        except Exception:
            import traceback
            traceback.print_exc()
            R.failed += 1
        finish()

    def setup_graph():
        S.reset_scene()
        with bpy.context.temp_override(**S.ui_context()):
            obj, d, e, _, _ = S.grid_setup("EMBEDDED")
            d.options_embedded.n_nodes = 40
            bpy.ops.deformkit.bind()
            e.location.z += 0.5
            d.options_embedded.show_graph = True
            bpy.context.view_layer.update()
        win = bpy.context.window_manager.windows[0]
        area = max(win.screen.areas, key=lambda a: a.width * a.height)
        area.type = "VIEW_3D"
        r3d = area.spaces.active.region_3d
        r3d.view_location = obj.location
        r3d.view_distance = 4.0
        r3d.view_rotation = Euler((1.0, 0.0, 0.6)).to_quaternion()
        R.check("embedded deformation bound", d.bound and not d.status_is_error, d.status)

    def shoot_graph():
        try:
            win = bpy.context.window_manager.windows[0]
            area = max(win.screen.areas, key=lambda a: a.width * a.height)
            before = S.overlay._state["draws"]
            window_shot(win, area, PNG3)
            R.check("Show Graph drew the graph", S.overlay._state["draws"] > before and
                    S.overlay._state["error"] is None, S.overlay._state)
            R.check("viewport screenshot saved", os.path.exists(PNG3))
        except Exception:
            import traceback
            traceback.print_exc()
            R.failed += 1
        finish()

    def fresh_properties():
        """An empty scene, its largest area the Properties editor (a generator: the editor
        takes the next event loop tick)."""
        S.reset_scene()
        win = bpy.context.window_manager.windows[0]
        area = max(win.screen.areas, key=lambda a: a.width * a.height)
        area.type = "PROPERTIES"
        yield None

    def bent_tube(method, n_len, status_words, **options):
        """A fresh scene's tube with a `method` deformer (S.tube_deformer), Advanced open,
        bound, its handle turned and moved, its modifier collapsed; checks that the status
        says `status_words`."""
        yield from fresh_properties()
        with bpy.context.temp_override(**S.ui_context()):
            obj, d, e, _, _ = S.tube_deformer(method, n_len=n_len, **options)
            d.show_advanced = True
            bpy.ops.deformkit.bind()
            e.location = (0.6, 0.7, 0.0)
            e.rotation_euler = (0.0, 0.0, 1.2)
        S.geonodes.find_modifier(obj, d).show_expanded = False
        R.check("%s bound on a tube, the status saying %r" % (method, status_words),
                d.bound and not d.status_is_error and status_words in S.solver.status_text(d),
                S.solver.status_text(d))

    def states():
        """A generator: puts the scene in each of STATES, yields (the shot is taken 0.8 s
        later, when the timer resumes it)."""
        import time

        import numpy as np
        S.reset_scene()
        win = bpy.context.window_manager.windows[0]
        area = max(win.screen.areas, key=lambda a: a.width * a.height)
        with bpy.context.temp_override(**S.ui_context()):
            obj, d, e, fixed, handle = S.grid_setup("ARAP")
        area.type = "PROPERTIES"
        S.geonodes.find_modifier(obj, d).show_expanded = False
        yield "unbound"
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.deformkit.bind()
            e.location.z += 0.4
            bpy.context.view_layer.update()
        yield "bound"
        # a loose vertex: the bind warns, and the panel keeps the warning under the status
        import bmesh
        S.add_loose_vertex(obj, (1.2, 0.5, 0.6))
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.deformkit.bind()
        R.check("the loose vertex's warning", len(S.solver.bind_warnings(obj, d)) == 1)
        yield "bound_warning"
        bm = bmesh.new()
        bm.from_mesh(obj.data)
        bm.verts.ensure_lookup_table()
        bm.verts.remove(bm.verts[len(bm.verts) - 1])
        bm.to_mesh(obj.data)
        bm.free()
        obj.data.update()
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.deformkit.bind()
        S.solver.threaded_rebinds[0] = True
        d.options.weights = "uniform" if d.options.weights != "uniform" else "cotangent"
        bpy.context.view_layer.update()
        # a 72-vertex bind ends in a millisecond: hold its installation back until the shot
        if bpy.app.timers.is_registered(S.handlers.poll_rebinds):
            bpy.app.timers.unregister(S.handlers.poll_rebinds)
        yield "rebinding"
        t0 = time.time()
        while S.solver.rebinding() and time.time() - t0 < 20:
            time.sleep(0.01)
            S.handlers.poll_rebinds()
        S.solver.threaded_rebinds[0] = None
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.wm.save_as_mainfile(filepath=os.path.join(OUT, "panel_states.blend"))
            e.keyframe_insert("location", frame=1)
            e.location.z += 0.2
            e.keyframe_insert("location", frame=10)
            bpy.ops.deformkit.bake(mode="PC2", frame_start=1, frame_end=10,
                                   filepath="//panel_states.pc2")
        yield "baked"
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.deformkit.free_bake()
        S.group(obj, "fixed", [int(handle[0]), int(handle[1])])
        bpy.context.view_layer.update()
        S.solver.evaluate_object(obj, bpy.context.evaluated_depsgraph_get(), check_groups=True)
        yield "overlap_error"
        for x in bpy.context.view_layer.objects:
            x.select_set(False)
        bpy.context.view_layer.objects.active = e
        e.select_set(True)
        yield "handle_target"
        # back to a bound state for the sidebar: the two handle vertices out of the fixed group
        obj.vertex_groups["fixed"].remove([int(handle[0]), int(handle[1])])
        bpy.context.view_layer.update()
        S.solver.evaluate_object(obj, bpy.context.evaluated_depsgraph_get(), check_groups=True)
        R.check("bound again for the sidebar", d.bound and not d.status_is_error, d.status)
        # the 3D View's sidebar on its DeformKit tab, the handle's empty still selected: the
        # deformer's status and Bind stay in view while the artist moves the handle. The
        # window suite runs in Debian's Blender 3.4, which has no Python setter for a
        # sidebar's tab (Region.active_panel_category came in 4.1), so the tab is clicked
        # with a simulated event; the panel's draw records that it ran, so a click that
        # missed the tab fails the check instead of shooting the Item tab.
        win = bpy.context.window_manager.windows[0]
        area = max(win.screen.areas, key=lambda a: a.width * a.height)
        area.type = "VIEW_3D"
        yield None  # the new editor's regions exist from the next tick on
        area.spaces.active.show_region_ui = True
        yield None
        reg = next(r for r in area.regions if r.type == "UI")
        if hasattr(reg, "active_panel_category"):
            reg.active_panel_category = "DeformKit"
        else:
            # the fourth tab (Item, Tool, View, DeformKit) at the factory UI scale: its
            # middle is 172 px below the region's top, 14 px from its right edge
            x, y = reg.x + reg.width - 14, reg.y + reg.height - 172
            win.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
            win.event_simulate(type="LEFTMOUSE", value="PRESS", x=x, y=y)
            win.event_simulate(type="LEFTMOUSE", value="RELEASE", x=x, y=y)
        sidebar_drawn.clear()
        yield "sidebar"
        R.check("the sidebar's DeformKit tab drew the deformer", bool(sidebar_drawn))
        # the deformers driven by a control object: a lattice made around a grid, one point
        # raised; a cage made around a sphere, a few of its vertices pulled
        yield from fresh_properties()
        with bpy.context.temp_override(**S.ui_context()):
            obj = S.make_grid(nx=24, ny=12)
            bpy.ops.deformkit.add_deformer(method="LATTICE")
            bpy.ops.deformkit.make_lattice()
            d = obj.deformkit.deformers[0]
            bpy.ops.deformkit.bind()
            lt = d.control_object.data
            lt.points[13].co_deform.z += 0.4
            lt.update_tag()
            bpy.context.view_layer.update()
        S.geonodes.find_modifier(obj, d).show_expanded = False
        R.check("the lattice deformer bound", d.bound and not d.status_is_error, d.status)
        yield "lattice"
        import bmesh
        S.reset_scene()
        me = bpy.data.meshes.new("Blob")
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=0.5)
        bm.to_mesh(me)
        bm.free()
        obj = S.linked_object("Blob", me)
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.deformkit.add_deformer(method="CAGE")
            bpy.ops.deformkit.make_cage(detail=1)
            d = obj.deformkit.deformers[0]
            bpy.ops.deformkit.bind()
            cage = d.control_object
            for v in cage.data.vertices:
                if v.co.z > 0.3:
                    v.co.z += 0.35
                    v.co.x += 0.2
            cage.data.update()
            bpy.context.view_layer.update()
        S.geonodes.find_modifier(obj, d).show_expanded = False
        R.check("the cage deformer bound", d.bound and not d.status_is_error, d.status)
        yield "cage"
        area.type = "VIEW_3D"
        yield None
        win = bpy.context.window_manager.windows[0]
        area = max(win.screen.areas, key=lambda a: a.width * a.height)
        sp = next(x for x in area.spaces if x.type == "VIEW_3D")
        sp.shading.type = "SOLID"
        r3d = sp.region_3d
        r3d.view_perspective = "PERSP"
        from mathutils import Euler, Vector
        r3d.view_rotation = Euler((1.2, 0.0, 0.6)).to_quaternion()
        r3d.view_location = Vector((0.0, 0.0, 0.15))
        r3d.view_distance = 3.2
        yield "cage_view"
        # a tube on a two-bone rig, its weights computed (Compute Weights), bound, the lower
        # bone bent: the elbow should bend smoothly, the ends stay round
        S.reset_scene()
        V, F = S.tube(n_len=41)
        obj = S.triangle_mesh_object(V, F, name="Tube")
        with bpy.context.temp_override(**S.ui_context()):
            arm, ao = S.two_bone_rig("Rig")
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        with bpy.context.temp_override(**S.ui_context()):
            bpy.ops.deformkit.add_deformer(method="SKINNING")
            d = obj.deformkit.deformers[0]
            d.control_object = ao
            bpy.ops.deformkit.compute_weights()
            bpy.ops.deformkit.bind()
        pb = ao.pose.bones["lower"]
        pb.rotation_mode = "XYZ"
        pb.rotation_euler = (0.0, 0.0, 1.0)
        bpy.context.view_layer.update()
        R.check("the skinning deformer bound on computed weights",
                d.bound and not d.status_is_error and len(obj.vertex_groups) == 2, d.status)
        win = bpy.context.window_manager.windows[0]  # the scene's reset made a new screen
        area = max(win.screen.areas, key=lambda a: a.width * a.height)
        area.type = "VIEW_3D"
        sp = next(x for x in area.spaces if x.type == "VIEW_3D")
        sp.shading.type = "SOLID"
        r3d = sp.region_3d
        r3d.view_perspective = "ORTHO"
        r3d.view_rotation = Euler((0.0, 0.0, 0.0)).to_quaternion()  # from the top
        r3d.view_location = Vector((0.2, 0.4, 0.0))
        r3d.view_distance = 3.0
        yield "skinning_view"
        # the Jiggle deformer after an Armature, its Region the forearm, played to frame 12:
        # the panel shows its options and the simulated range
        yield from fresh_properties()
        with bpy.context.temp_override(**S.ui_context()):
            obj = S.make_grid(nx=24, ny=6)
            rest = S.rest_positions(obj)
            S.group(obj, "forearm", np.flatnonzero(rest[:, 0] > -0.2))
            S.arm_rig(obj, {"lower": ((1, (0, 0, 0)), (10, (0.8, 0, 0)), (20, (0, 0, 0)))})
            bpy.context.view_layer.objects.active = obj
            obj.select_set(True)
            bpy.ops.deformkit.add_deformer(method="SHAPE_MATCHING")
            d = obj.deformkit.deformers[0]
            d.roi_group = "forearm"
            sc = bpy.context.scene
            sc.frame_start, sc.frame_end = 1, 40
            sc.frame_set(1)
            bpy.ops.deformkit.bind()
            for f in range(1, 13):
                sc.frame_set(f)
        S.geonodes.find_modifier(obj, d).show_expanded = False
        R.check("the jiggle deformer bound and played",
                d.bound and not d.status_is_error and
                "1-12" in (S.solver.simulation_text(obj, d) or ""),
                (d.status, S.solver.simulation_text(obj, d)))
        yield "jiggle"
        # the Shape Blend deformer on a rigged tube with a key twisted by 360 degrees at 0.5:
        # added above the Armature, its options (Advanced open)
        yield from fresh_properties()
        with bpy.context.temp_override(**S.ui_context()):
            V, F = S.tube(n_len=41)
            obj = S.triangle_mesh_object(V, F, name="Tube")
            rest = S.rest_positions(obj)
            S.arm_rig(obj, {"lower": ((1, (0, 0, 0.4)),)})
            bpy.context.view_layer.objects.active = obj
            obj.select_set(True)
            obj.shape_key_add(name="Basis")
            kb = obj.shape_key_add(name="Twist", from_mix=False)
            t = (rest[:, 0] - rest[:, 0].min()) / np.ptp(rest[:, 0]) * 2 * np.pi
            P = rest.copy()
            P[:, 1] = np.cos(t) * rest[:, 1] - np.sin(t) * rest[:, 2]
            P[:, 2] = np.sin(t) * rest[:, 1] + np.cos(t) * rest[:, 2]
            kb.data.foreach_set("co", P.astype(np.float32).ravel())
            kb.value = 0.5
            bpy.ops.deformkit.add_deformer(method="SHAPE_BLEND")
            d = obj.deformkit.deformers[0]
            d.show_advanced = True
            bpy.ops.deformkit.bind()
        S.geonodes.find_modifier(obj, d).show_expanded = False
        R.check("the shape blend deformer bound above the Armature",
                d.bound and not d.status_is_error and obj.modifiers[0].type == "NODES",
                (d.status, [m.type for m in obj.modifiers]))
        yield "shape_blend"
        # the Volume ARAP deformer on a tube bent by its handle, Coarse Level 2: bound, its
        # status counting the tetrahedra and naming the level, its options (Advanced open)
        yield from bent_tube("VOLUME_ARAP", 41, "coarse level of", levels=2)
        yield "volume_arap"
        # ARAP with a coarse level (Coarse Levels 2 on a tube): bound, its status naming the
        # level, its options (Advanced open, Coarse Levels among them)
        yield from bent_tube("ARAP", 61, "coarse level of", levels=2)
        yield "arap_levels"

    sidebar_drawn = []
    from addon import ui
    panel = ui.DEFORMKIT_PT_sidebar
    original_draw = panel.draw

    def recording_draw(self, context):
        obj = context.object
        sidebar_drawn.append(obj.name if obj is not None else None)
        original_draw(self, context)
    panel.draw = recording_draw

    def shoot_states():
        gen = states()

        def tick():
            try:
                name = next(gen, "")
                if name == "":
                    finish()
                    return None
                if name is None:  # a step that needs the next event loop tick
                    bpy.app.timers.register(tick, first_interval=0.2)
                    return None
                win = bpy.context.window_manager.windows[0]
                area = max(win.screen.areas, key=lambda a: a.width * a.height)

                def shot(name=name, win=win, area=area):
                    path = os.path.join(OUT, "panel_%s.png" % name)
                    if area.type == "PROPERTIES":
                        area.spaces.active.context = \
                            "OBJECT" if name == "handle_target" else "MODIFIER"
                    window_shot(win, area, path)
                    R.check("panel state %s shot" % name, os.path.exists(path))
                    bpy.app.timers.register(tick, first_interval=0.1)
                    return None
                bpy.app.timers.register(shot, first_interval=0.8)
            except Exception:
                import traceback
                traceback.print_exc()
                R.failed += 1
                finish()
            return None
        return tick

    shot_kind = os.environ.get("DEFORMKIT_SHOT")
    graph_run = shot_kind == "graph"

    def first():
        if shot_kind == "states":
            bpy.app.timers.register(shoot_states(), first_interval=0.5)
            return None
        try:
            setup_graph() if graph_run else setup()
        except Exception:
            import traceback
            traceback.print_exc()
            R.failed += 1
        bpy.app.timers.register(shoot_graph if graph_run else shoot, first_interval=1.5)
        return None

    bpy.app.timers.register(first, first_interval=1.0)


if IN_BLENDER:
    in_blender()
else:
    launch()

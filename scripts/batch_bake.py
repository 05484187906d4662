"""Headless DeformKit bake: solves every frame of a range and writes a PC2 point cache.

  blender -b scene.blend --python-exit-code 1 --python scripts/batch_bake.py -- \
      --object NAME [--deformer NAME] --frames A-B --out FILE.pc2 [--checkpoints DIR] [--save]
  blender -b --python-exit-code 1 --python scripts/batch_bake.py -- --join a.pc2 b.pc2 --out all.pc2
  python3 scripts/batch_bake.py --join a.pc2 b.pc2 --out all.pc2      (join needs no Blender)
  python scripts/batch_bake.py --blend scene.blend [--scene NAME] --object NAME ...
                                 (Blender as a Python module: a venv with the `bpy` wheel)
  ... --object NAME [--deformer NAME] [--out FILE.pc2] --describe FILE.json
                                 (what a bake would do, for scripts/farm_bake.py: no solving)

Each frame is solved from a cold start, so a frame's result depends only on that frame's inputs:
ranges baked on different machines and joined equal one bake of the whole range. A simulation
(Jiggle) is the exception: each frame follows from the one before, so a range starting after
the scene's first frame either plays the frames before it, or, with --checkpoints DIR,
continues from the checkpoint the chunk before it left there (chunks then run in order); both
equal one bake, bit for bit. If the
deformer is not bound, it is bound at the scene's start frame (the same on every machine).
--save adds a Mesh Cache modifier reading the cache (in place of the deformer's modifier) and
saves the .blend. --describe writes the scene's frame range, the deformer's method, whether
it is a simulation (chunks must then run in order) and the vertex count as JSON, after checking
--out as a bake would. Progress lines go to stderr; any failure exits non-zero.
"""

import argparse
import importlib.util
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def log(msg):
    sys.stderr.write("batch_bake: %s\n" % msg)
    sys.stderr.flush()


def running_as_module():
    """True under Blender as a Python module (`import bpy` in a plain Python), False under the
    blender program or without bpy."""
    bpy = sys.modules.get("bpy")
    return bpy is not None and not bpy.app.binary_path


def leave(code):
    """Exits with `code`. The bpy module (4.5, 5.0) can hang in its exit handlers once a file
    was written, so there the process ends at once, its output flushed."""
    sys.stdout.flush()
    sys.stderr.flush()
    if running_as_module():
        os._exit(code)
    sys.exit(code)


def fail(msg):
    log("error: " + msg)
    leave(1)


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """A usage error is a failure like any other: said as one, exit status 1."""
        self.print_usage(sys.stderr)
        fail(message)


def parse(argv):
    argv = argv[argv.index("--") + 1:] if "--" in argv else argv[1:]
    p = _Parser(prog="batch_bake.py", description=__doc__.split("\n")[0])
    p.add_argument("--blend", help="open this .blend first (for Blender as a Python module; "
                                   "the blender program takes the file before --python)")
    p.add_argument("--scene", help="with --blend: the scene to bake in (default: the file's)")
    p.add_argument("--object", help="name of the deformed mesh object")
    p.add_argument("--deformer", help="deformer name (default: the object's active deformer)")
    p.add_argument("--frames", help="frame range A-B (inclusive); default: the scene's range "
                                    "(from below zero: --frames=-5-10)")
    p.add_argument("--out",
                   help="output .pc2 file (a path starting with // is relative to the .blend, "
                        "as in Blender); its folder must exist, and an existing file there is "
                        "only replaced if it is a point cache")
    p.add_argument("--join", nargs="+", metavar="PC2", help="join these caches into --out")
    p.add_argument("--checkpoints", metavar="DIR",
                   help="a simulation (Jiggle): continue from DIR's checkpoint of the frame "
                        "before --frames when there is one (else play the frames before the "
                        "range), and leave the checkpoint of the range's last frame there "
                        "for the next chunk")
    p.add_argument("--save", action="store_true",
                   help="add a Mesh Cache modifier reading --out and save the .blend")
    p.add_argument("--describe", metavar="JSON",
                   help="write what a bake would do into this file (frame range, method, "
                        "simulation or not, vertices; --out checked if given) and stop")
    return p.parse_args(argv)


def load_pc2_module():
    """addon/pc2.py without importing the add-on package (no bpy needed)."""
    spec = importlib.util.spec_from_file_location("deformkit_pc2", os.path.join(ROOT, "addon", "pc2.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def do_join(args):
    pc2 = load_pc2_module()
    if args.out.startswith("//"):
        fail("--out %s: a // path is relative to a .blend, and joining opens none: give a "
             "plain path" % args.out)
    for p in args.join:
        if not os.path.isfile(p):
            fail("no such cache: %s" % p)
    try:
        info = pc2.join(args.join, args.out)
    except (pc2.PC2Error, OSError) as e:
        fail(str(e))
    log("joined %d caches into %s: %d points, frames %g-%g"
        % (len(args.join), args.out, info["points"], info["start"],
           info["start"] + (info["samples"] - 1) * info["rate"]))


def ensure_addon():
    """The DeformKit add-on package, registered: the one already enabled, else the one
    installed in this Blender (legacy add-on or extension), else the repository's addon/.
    addon_utils.enable is only asked for a package it lists: for any other name it prints
    an "Add-on not loaded" traceback even when the run then succeeds."""
    import bpy
    if hasattr(bpy.types.Object, "deformkit") and hasattr(bpy.ops, "deformkit"):
        for name in ("addon", "deformkit_addon", "bl_ext.user_default.deformkit_addon"):
            m = sys.modules.get(name)
            if m is not None and hasattr(m, "solver"):
                return m
    import addon_utils
    installed = [m.__name__ for m in addon_utils.modules()
                 if m.__name__.split(".")[-1] == "deformkit_addon"]
    for name in installed:
        try:
            mod = addon_utils.enable(name, default_set=False)
        except Exception as e:  # a broken install: say so, then use the repository's
            log("the installed add-on %s could not be enabled (%s): using %s"
                % (name, e, os.path.join(ROOT, "addon")))
            continue
        if mod is not None and hasattr(mod, "solver"):
            return mod
    if not os.path.isfile(os.path.join(ROOT, "addon", "__init__.py")):
        fail("the DeformKit add-on is not installed in this Blender (%s), and there is no "
             "addon/ folder beside this script: install the add-on's zip in it"
             % bpy.app.version_string)
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    import addon
    addon.register()
    return addon


def parse_frames(text, scene):
    if not text:
        return scene.frame_start, scene.frame_end
    try:   # the "-" after the first character: "-5-10" is frames -5 to 10
        cut = text.index("-", 1) if "-" in text[1:] else -1
        a, b = (text[:cut], text[cut + 1:]) if cut > 0 else (text, text)
        a, b = int(a), int(b)
    except ValueError:
        fail("--frames must look like A-B, got %r" % text)
    if b < a:
        fail("empty frame range %d-%d" % (a, b))
    return a, b


def open_target(args):
    """Opens --blend (and --scene) when given, registers the add-on and finds the object and
    its deformer: (add-on module, scene, object, deformer). Fails with a message otherwise."""
    import bpy
    if not args.object:
        fail("--object NAME is required (or --join)")
    if args.blend:
        if not os.path.isfile(args.blend):
            fail("no such .blend file: %s" % args.blend)
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend), load_ui=False)
        if args.scene:
            sc = bpy.data.scenes.get(args.scene)
            if sc is None:
                fail("%s has no scene %r (has: %s)" % (args.blend, args.scene,
                                                     ", ".join(x.name for x in bpy.data.scenes)))
            wins = bpy.context.window_manager.windows
            if not len(wins):
                fail("--scene: this Blender has no window to switch scenes in")
            wins[0].scene = sc
    ext = ensure_addon()
    if ext.native.load() is None:
        fail(ext.native.error)
    scene = bpy.context.scene
    obj = bpy.data.objects.get(args.object)
    if obj is None:
        fail("no object named %r in %s" % (args.object, bpy.data.filepath or "the scene"))
    if obj.type != "MESH":
        fail("%r is %s, not a mesh" % (obj.name, ext.text.article(obj.type.lower())))
    dks = obj.deformkit
    if len(dks.deformers) == 0:
        fail("%r has no DeformKit deformer" % obj.name)
    if args.deformer:
        d = dks.deformers.get(args.deformer)
        if d is None:
            fail("%r has no deformer %r (has: %s)" % (obj.name, args.deformer,
                                                    ", ".join(x.name for x in dks.deformers)))
    else:
        d = dks.deformers[min(dks.active_index, len(dks.deformers) - 1)]
    return ext, scene, obj, d


def do_describe(args):
    import json
    import bpy
    ext, scene, obj, d = open_target(args)
    a, b = parse_frames(args.frames, scene)
    out = None
    if args.out:
        try:
            out = ext.bake.check_cache_path(obj, d, ext.bake.resolve_path(args.out, obj, d))
        except ext.solver.DeformKitError as e:
            fail(str(e))
    info = {"blend": bpy.data.filepath, "scene": scene.name, "object": obj.name,
            "deformer": d.name, "method": d.method, "bound": bool(d.bound),
            "simulation": bool(ext.solver.simulation.is_dynamic(ext.methods.get(d.method))),
            "vertices": len(obj.data.vertices), "frame_start": a, "frame_end": b,
            "scene_frame_start": scene.frame_start, "fps": scene.render.fps / scene.render.fps_base,
            "out": out, "protected": [list(p) for p in ext.bake.protected_files(obj, d)]}
    part = args.describe + ".part"
    with open(part, "w") as f:
        json.dump(info, f)
    os.replace(part, args.describe)
    log("described '%s' of %r: %s, frames %d-%d, %d vertices%s"
        % (d.name, obj.name, d.method, a, b, info["vertices"],
           ", a simulation (chunks in order)" if info["simulation"] else ""))


def do_bake(args):
    import bpy
    ext, scene, obj, d = open_target(args)
    solver, bake = ext.solver, ext.bake
    a, b = parse_frames(args.frames, scene)
    if args.save and not bpy.data.filepath:
        fail("--save needs a .blend file (open one with --blend, or give it to blender)")
    if not args.out:
        fail("--out is empty: give the .pc2 file to write")
    try:
        out = bake.resolve_path(args.out, obj, d)   # "//" as in Blender: next to the .blend
        bake.check_cache_path(obj, d, out)         # before binding or solving anything
        # a deformer baked in the file: its own modifier shown for this run (its frames read
        # what reaches it there: a rig's pose), the earlier bake set aside; the file on disk
        # is unchanged unless --save, which replaces that bake by this one
        bake.SetAside(obj, d, "PC2", register=False)
        if not d.bound:
            rest = solver.rest_frame(scene, d)
            log("'%s' is not bound: binding with the rest of frame %d" % (d.name, rest))
            scene.frame_set(rest)
            solver.bind(obj, d, bpy.context.evaluated_depsgraph_get())
        t_start = time.perf_counter()
        last = [t_start]
        n = b - a + 1

        def progress(i, total, frame):
            now = time.perf_counter()
            log("frame %d (%d/%d, %d%%) %.1f ms" % (frame, i, total, 100 * i // total,
                                                    (now - last[0]) * 1000))
            last[0] = now

        folder = os.path.abspath(args.checkpoints) if args.checkpoints else None
        if folder and not os.path.isdir(folder):
            fail("--checkpoints: no folder %s" % folder)
        if folder:
            got = bake.load_checkpoint(obj, d, folder, a)
            log("continuing from the checkpoint of frame %d (%s)" % (a - 1, got) if got else
                "no checkpoint of frame %d in %s: playing from frame %d"
                % (a - 1, folder, scene.frame_start))
        bake.bake_pc2(bpy.context, obj, d, a, b, out, progress)
        if folder:
            saved = bake.save_checkpoint(obj, d, folder, b)
            if saved:
                log("left the checkpoint of frame %d: %s" % (b, saved))
        log("wrote %s: %d frames x %d vertices in %.2f s"
            % (out, n, len(obj.data.vertices), time.perf_counter() - t_start))
        if args.save:
            bake.add_mesh_cache(obj, d, out, a, b)
            bpy.ops.wm.save_mainfile()
            log("added a Mesh Cache modifier and saved %s" % bpy.data.filepath)
    except solver.DeformKitError as e:
        fail(str(e))


def main():
    args = parse(sys.argv)
    if not args.describe and not args.out:
        fail("--out FILE is required: the .pc2 file to write")
    try:
        if args.join:
            do_join(args)
        elif args.describe:
            do_describe(args)
        else:
            do_bake(args)
    except SystemExit:
        raise
    except Exception as e:  # anything unexpected: non-zero exit with the message
        import traceback
        traceback.print_exc()
        fail("%s: %s" % (type(e).__name__, e))
    leave(0)


if __name__ == "__main__":
    main()

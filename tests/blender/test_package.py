"""A packaged zip as a user gets it, installed into a clean user directory with no build tree
on the path: in Blender 4.2+ the extension zip (Install from Disk; Blender installs the wheel
that its manifest lists), before 4.2 the legacy zip (Preferences > Add-ons > Install). Checks
that the installed copy, its native module and the module's bundled shared libraries are the
ones in use, then deforms a small mesh with each method through the add-on's operators, and
disables and re-enables the add-on.

Run by tests/blender/run_all.sh after scripts/package.sh, as (legacy zip, Blender 3.4)
    env -u PYTHONPATH BLENDER_USER_SCRIPTS=<fresh dir> BLENDER_USER_CONFIG=<fresh dir> \\
        DEFORMKIT_FROM_ZIP=dist/deformkit_addon-<version>-legacy-linux_x64.zip \\
        blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_package.py
or (extension zip, a bpy wheel's Python)
    env -u PYTHONPATH BLENDER_USER_RESOURCES=<fresh dir> \\
        DEFORMKIT_FROM_ZIP=dist/deformkit_addon-<version>-linux_x64.zip \\
        build/venvs/bpy-5.3/bin/python tests/blender/test_package.py
(_setup.py does the install and enable when DEFORMKIT_FROM_ZIP is set)."""
import os
import re
import subprocess
import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
if not os.environ.get("DEFORMKIT_FROM_ZIP"):
    print("FAIL set-up: set DEFORMKIT_FROM_ZIP to a packaged zip (tests/blender/run_all.sh does)")
    print("test_package: 0 passed, 1 failed")
    sys.exit(1)
import _setup as S  # noqa: E402  (installs and enables the zip)
import addon_utils  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

R = S.Results("test_package")
EXTENSION = S.zip_is_extension(os.environ["DEFORMKIT_FROM_ZIP"])
if EXTENSION:
    ROOT = os.path.realpath(os.path.join(bpy.utils.user_resource("EXTENSIONS"), "user_default",
                                         S.PACKAGE))
    # where Blender installs the wheels of extensions
    NATIVE = os.path.realpath(os.path.join(
        bpy.utils.user_resource("EXTENSIONS"), ".local", "lib",
        "python%d.%d" % sys.version_info[:2], "site-packages", "deformkit"))
else:
    ROOT = os.path.realpath(os.path.join(bpy.utils.user_resource("SCRIPTS", path="addons"),
                                         S.PACKAGE))
    NATIVE = os.path.join(ROOT, "deformkit")
LIBS = os.path.join(os.path.dirname(NATIVE), "deformkit.libs")


def inside(path, folder):
    return os.path.realpath(path).startswith(folder + os.sep)


def mapped_files():
    out = set()
    with open("/proc/self/maps") as f:
        for line in f:
            parts = line.split(None, 5)
            if len(parts) == 6 and parts[5].startswith("/"):
                out.add(os.path.realpath(parts[5].strip()))
    return out


def test_installed_copy_in_use():
    zip_name = os.path.basename(os.environ["DEFORMKIT_FROM_ZIP"])
    m = re.match(r"%s-(\d+)\.(\d+)\.(\d+)-%s" % (S.PACKAGE, "" if EXTENSION else "legacy-"),
                 zip_name)
    R.check("zip name carries the version", m is not None, zip_name)
    if EXTENSION:
        R.check("extension installed with its manifest and its wheel",
                os.path.isfile(os.path.join(ROOT, "blender_manifest.toml"))
                and any(f.endswith(".whl") for f in os.listdir(os.path.join(ROOT, "wheels"))),
                sorted(os.listdir(ROOT)))
        R.check("enabled as an extension", S.ADDON_NAME == "bl_ext.user_default." + S.PACKAGE
                and S.addon.__name__ == S.ADDON_NAME, (S.ADDON_NAME, S.addon.__name__))
        R.check("the wheel is installed with its metadata",
                any(f.startswith("deformkit-") and f.endswith(".dist-info")
                    for f in os.listdir(os.path.dirname(NATIVE))), os.path.dirname(NATIVE))
        R.check("no native module copied into the add-on folder",
                not os.path.exists(os.path.join(ROOT, "deformkit")))
    else:
        R.check("add-on installed as a folder with the native package",
                all(os.path.isfile(os.path.join(ROOT, p)) for p in
                    ("__init__.py", "deformkit/__init__.py", "deformkit/_native.abi3.so",
                     "deformkit.libs/THIRD-PARTY-NOTICES.txt")), sorted(os.listdir(ROOT)))
        R.check("no manifest in the legacy install",
                not os.path.exists(os.path.join(ROOT, "blender_manifest.toml")))
    R.check("enabled add-on is the installed copy", inside(S.addon.__file__, ROOT),
            S.addon.__file__)
    R.check("enabled in the preferences", S.ADDON_NAME in bpy.context.preferences.addons)
    if m and EXTENSION:   # Blender reads an extension's version from its manifest
        import tomllib
        with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as f:
            man = tomllib.load(f)
        R.check("manifest version = zip version", man["version"] == "%s.%s.%s" % m.groups(),
                (man["version"], zip_name))
    elif m:
        v = tuple(int(x) for x in m.groups())
        R.check("bl_info version = zip version", tuple(S.addon.bl_info["version"]) == v,
                (S.addon.bl_info["version"], v))
    R.check("native module loaded without error", S.native.module is not None and
            not S.native.error, S.native.error)
    dk = S.native.module
    R.check("native module is the installed one",
            dk is not None and inside(dk.__file__, NATIVE)
            and inside(dk._native.__file__, NATIVE), getattr(dk, "__file__", None))
    R.check("bundled notices installed",
            os.path.isfile(os.path.join(LIBS, "THIRD-PARTY-NOTICES.txt")), LIBS)
    others = [p for p in sys.path if os.path.isdir(p)
              and os.path.realpath(os.path.join(p, "deformkit")) != NATIVE
              and os.path.exists(os.path.join(p, "deformkit", "_native.abi3.so"))]
    R.check("no other native module on sys.path (no build/python)", not others, others)


def blender_own_libraries():
    """Files Blender's executable (or the bpy module's binary) links itself (Debian's links
    OpenBLAS, LAPACK, libgfortran, libgomp, and ARPACK through Armadillo): those system copies
    are in the process anyway."""
    binary = bpy.app.binary_path or next(
        p for p in mapped_files() if p.endswith(os.sep + os.path.join("bpy", "__init__.so")))
    out = subprocess.run(["ldd", binary], capture_output=True, text=True).stdout
    return {os.path.realpath(m) for m in re.findall(r"=> (/\S+)", out)}


def test_bundled_libraries_loaded():
    bundled = sorted(f for f in os.listdir(LIBS) if ".so" in f)
    R.check("libraries bundled", len(bundled) >= 5, bundled)
    mapped = mapped_files()
    missing = [b for b in bundled if os.path.join(LIBS, b) not in mapped]
    R.check("every bundled library is loaded from the add-on", not missing, missing)
    own = blender_own_libraries()
    R.check("Blender's own libraries listed", len(own) > 5, len(own))
    # the system files' names: auditwheel's without the hash (libcholmod-1a2b3c4d.so.3.0.14
    # was libcholmod.so.3.0.14)
    originals = {re.sub(r"-[0-9a-f]{8}(?=\.)", "", b) for b in bundled}
    system = sorted(p for p in mapped - own if not p.startswith(LIBS + os.sep)
                    and os.path.basename(p) in originals)
    R.check("no system copy of a bundled library loaded beyond Blender's own", not system, system)


def test_native_calls():
    """One call per bundled numerical library, from Blender's Python."""
    dk = S.dk
    obj = S.make_grid("NativeGrid", nx=8, ny=5)
    mesh = dk.Mesh(S.solver.rest_positions(obj.data), S.solver.triangles(obj.data))
    evals, _ = dk.laplacian_eigenpairs(mesh, 3)                       # ARPACK
    R.check("eigenpairs: constant mode first", abs(evals[0]) < 1e-6 and evals[1] > 1e-3,
            list(evals))
    rot = dk.closest_rotation(np.array([[0, -2.0, 0], [2, 0, 0], [0, 0, 2]]))  # LAPACKE
    R.check("closest_rotation", np.abs(np.asarray(rot) - [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
            .max() < 1e-9, rot)
    bpy.data.objects.remove(obj)


def test_deform_end_to_end():
    for mid in [m.id for m in S.handle_methods()]:
        S.reset_scene()  # also re-enables the add-on (factory settings disable it)
        nx, ny = 10, 5
        obj = S.make_grid(nx=nx, ny=ny)
        fixed = [j * nx + i for j in range(ny) for i in range(2)]
        handle = [j * nx + i for j in range(ny) for i in range(nx - 2, nx)]
        S.group(obj, "fixed", fixed)
        S.group(obj, "tip", handle)
        e = S.empty("Tip", (1.0, 0.0, 0.0))
        bpy.ops.deformkit.add_deformer(method=mid)
        d = obj.deformkit.deformers[0]
        d.fixed_group = "fixed"
        bpy.ops.deformkit.add_handle(vertex_group="tip", target=e.name)
        bpy.ops.deformkit.bind()
        R.check("%s bound" % mid, d.bound and not d.status_is_error, d.status)
        rest = S.rest_positions(obj)
        R.check("%s at bind = rest" % mid,
                np.abs(S.evaluated_positions(obj) - rest).max() < 2e-5)
        e.location = (1.0, 0.0, 0.4)
        bpy.context.view_layer.update()
        got = S.evaluated_positions(obj)
        want_h = rest[handle] + [0.0, 0.0, 0.4]
        m = S.methods.get(mid)   # penalty handles (the native contract's flag): most of the way
        flags = S.native.module._native._method_info(m.native_class)
        soft = flags["soft_regions"]   # a least-squares fit: most of the way, on average
        herr = np.abs(got[handle] - want_h).max(axis=1)
        R.check("%s handle vertices follow the target" % mid,
                herr.mean() < 0.1 if soft else
                herr.max() < (0.02 if flags["penalty_handles"] else 1e-4), herr.max())
        ferr = np.abs(got[fixed] - rest[fixed]).max(axis=1)
        R.check("%s fixed vertices stay" % mid,
                ferr.mean() < 0.1 if soft else ferr.max() < 1e-5, ferr.max())
        free = [i for i in range(nx * ny) if i not in set(fixed) | set(handle)]
        if S.solver.simulation.is_dynamic(m):
            # a simulation swings after the handle as frames play: finite, lifted, not flung
            sc = bpy.context.scene
            sc.frame_start, sc.frame_end = 1, 24
            for f in range(1, 25):
                sc.frame_set(f)
            dz = (S.evaluated_positions(obj)[free] - rest[free])[:, 2]
            R.check("%s the rest of the mesh swings after the handle" % mid,
                    np.isfinite(dz).all() and 0.1 < dz.max() < 0.8, (dz.min(), dz.max()))
            R.check("%s base mesh untouched" % mid,
                    np.abs(S.rest_positions(obj) - rest).max() == 0)
            continue
        dz = (got[free] - rest[free])[:, 2]
        # between 0 and the handle's lift; penalty-handle methods (embedded deformation: a
        # least-squares model with free rotations) within their handle tolerance of it
        R.check("%s the rest of the mesh moved in between" % mid,
                dz.max() > (0.05 if soft else 0.1)
                and dz.max() < 0.4 + (0.02 if flags["penalty_handles"] else 1e-6)
                and dz.min() > (-0.05 if soft else -0.02 if flags["penalty_handles"]
                                else -1e-3),
                (dz.min(), dz.max()))
        R.check("%s base mesh untouched" % mid, np.abs(S.rest_positions(obj) - rest).max() == 0)


def test_control_deformers_end_to_end():
    """The methods driven by a control object, from the packaged add-on: Make Lattice or
    Make Cage (or an armature of one bone), Bind, then the control (the bone) translated
    moves the mesh by the translation."""
    for m in S.methods.METHODS:
        if m in S.handle_methods():
            continue
        S.reset_scene()
        obj = S.make_grid(nx=10, ny=5)
        bpy.ops.deformkit.add_deformer(method=m.id)
        d = obj.deformkit.deformers[0]
        c = S.solver.controls.of(d)
        pb = None
        if c.OBJECT_TYPE == "ARMATURE":
            # bones: an armature of one bone, its weights computed (the one group, all 1)
            arm, ao = S.armature_in_edit_mode("Rig")
            b = arm.edit_bones.new("b")
            b.head, b.tail = (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)
            bpy.ops.object.mode_set(mode="OBJECT")
            bpy.context.view_layer.objects.active = obj
            d.control_object = ao
            getattr(bpy.ops.deformkit, c.MAKE_OPERATOR.split(".")[1])()
            R.check("%s: %s made the bone's group" % (m.id, c.MAKE_OPERATOR),
                    obj.vertex_groups.get("b") is not None)
            pb = ao.pose.bones["b"]
        else:
            getattr(bpy.ops.deformkit, c.MAKE_OPERATOR.split(".")[1])()
        bpy.ops.deformkit.bind()
        R.check("%s bound" % m.id, d.bound and not d.status_is_error, d.status)
        rest = S.rest_positions(obj)
        if pb is not None:
            pb.location.z += 0.3   # the bone along y: its z is the world's
        else:
            d.control_object.location.z += 0.3
        bpy.context.view_layer.update()
        err = np.abs(S.evaluated_positions(obj) - (rest + [0.0, 0.0, 0.3])).max()
        R.check("%s: the control's move moves the mesh (%.1e)" % (m.id, err), err < 1e-5)
        R.check("%s base mesh untouched" % m.id,
                np.abs(S.rest_positions(obj) - rest).max() == 0)


def test_disable_enable():
    addon_utils.disable(S.ADDON_NAME, default_set=True)
    try:
        bpy.ops.deformkit.add_deformer.get_rna_type()
        gone = False
    except KeyError:
        gone = True
    R.check("disable removes the operators", gone)
    R.check("disable clears the preference entry",
            S.ADDON_NAME not in bpy.context.preferences.addons)
    again = S._enable_installed()
    R.check("re-enable keeps the same package", again is S.addon)
    S.reset_scene()
    S.make_grid()
    bpy.ops.deformkit.add_deformer(method="ARAP")
    R.check("operators work after re-enable", len(bpy.context.object.deformkit.deformers) == 1)


for t in (test_installed_copy_in_use, test_bundled_libraries_loaded, test_native_calls,
          test_deform_end_to_end, test_control_deformers_end_to_end,
          test_disable_enable):
    R.run(t)
R.finish()

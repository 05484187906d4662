#!/usr/bin/env python3
"""Builds the two installable DeformKit zips into dist/ (called by scripts/package.sh, which
builds the native module first):

  deformkit-<version>-<platform>.zip         Blender 4.2+ extension: blender_manifest.toml and
                                             the add-on files at the zip root
  deformkit-<version>-legacy-<platform>.zip  Blender 3.4-4.1 add-on: one folder deformkit/
                                             with bl_info in its __init__.py

Both carry the native module as the subpackage deformkit/ of the add-on (addon/native.py looks
there first) together with every shared library it needs that is not part of glibc (or
libgcc_s), copied from the build machine into deformkit/libs/ under a unique name
(lib<name>-<hash>.so.N: a library of the same SONAME already loaded in Blender cannot stand in
for it) and found through RUNPATH ($ORIGIN/libs on the module, $ORIGIN on each library).
See docs/addon.md, "Packaging".

blender_manifest.toml is the single source of truth for id, version, name and tagline:
bl_info in addon/__init__.py, the native package's __version__ and CMake's project version
must agree with it, or nothing is written. Each zip is then checked: its layout, every ELF
dependency resolving inside the bundle, and an import plus small solves (CHOLMOD, ARPACK,
LAPACKE, BLAS) of the extracted module in a fresh Python with the system copies of the bundled
libraries hidden (when a private mount namespace is available) and /proc/self/maps showing the
bundled files in use. `blender --command extension validate` runs when the installed Blender
has it (4.2+).
"""
import argparse
import ast
import hashlib
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
import tomllib
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Libraries every Linux system that runs Blender has, never bundled: glibc's parts (the loader,
# libc, libm, ...) and libgcc_s (GCC's unwinder; two copies in one process is worse than
# relying on the system's). Everything else the module needs goes into the zip.
SYSTEM_SONAMES = {
    "linux-vdso.so.1", "ld-linux-x86-64.so.2", "ld-linux-aarch64.so.1", "libc.so.6",
    "libm.so.6", "libmvec.so.1", "libpthread.so.0", "libdl.so.2", "librt.so.1",
    "libutil.so.1", "libresolv.so.2", "libanl.so.1", "libnsl.so.1", "libgcc_s.so.1",
}

# Values Blender 4.2's manifest validation accepts (our own subset of its rules, checked even
# where that Blender is not installed).
KNOWN_PLATFORMS = {"windows-x64", "windows-arm64", "macos-x64", "macos-arm64", "linux-x64"}
KNOWN_PERMISSIONS = {"files", "network", "clipboard", "camera", "microphone"}
TERSE_MAX = 64


class PackageError(Exception):
    pass


def log(msg):
    print("package: " + msg, flush=True)


def run(cmd, **kw):
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if p.returncode != 0:
        raise PackageError("%s failed (exit %d):\n%s%s" % (" ".join(cmd), p.returncode,
                                                           p.stdout, p.stderr))
    return p.stdout


# ------------------------------------------------------------------------- metadata ----

def literal_assignment(path, name):
    """The literal value assigned to `name` at module level of a Python file (not imported:
    addon/__init__.py imports bpy)."""
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == name for t in node.targets):
            return ast.literal_eval(node.value)
    raise PackageError("%s: no top-level assignment to %s" % (path, name))


def check_terse(what, value, errors):
    if not isinstance(value, str) or not value.strip():
        errors.append("%s must be a non-empty string" % what)
        return
    if len(value) > TERSE_MAX:
        errors.append("%s is %d characters, Blender allows at most %d: %r"
                      % (what, len(value), TERSE_MAX, value))
    if not (value[-1].isalnum() or value[-1] in ")]}"):
        errors.append("%s must not end with punctuation: %r" % (what, value))
    if re.search(r"[\x00-\x1f\x7f-\x9f]", value):
        errors.append("%s contains control characters" % what)


def read_metadata():
    """Manifest, checked against Blender's extension rules and against every other place that
    states the version/name/tagline. Raises PackageError listing every disagreement."""
    manifest_path = os.path.join(ROOT, "blender_manifest.toml")
    with open(manifest_path, "rb") as f:
        man = tomllib.load(f)
    errors = []
    for key in ("schema_version", "id", "version", "name", "tagline", "maintainer", "type",
                "license", "blender_version_min"):
        if key not in man:
            errors.append("blender_manifest.toml: missing %s" % key)
    if errors:
        raise PackageError("\n".join(errors))
    if not (man["id"].isidentifier() and not man["id"].startswith("_")):
        errors.append("manifest id %r must be a Python identifier" % man["id"])
    m = re.fullmatch(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)", man["version"])
    if not m:
        errors.append("manifest version %r must be MAJOR.MINOR.PATCH (bl_info needs a tuple of "
                      "three numbers)" % man["version"])
    check_terse("manifest tagline", man["tagline"], errors)
    if man["type"] != "add-on":
        errors.append("manifest type must be \"add-on\", not %r" % man["type"])
    if not re.fullmatch(r"\d+\.\d+\.\d+", man["blender_version_min"]):
        errors.append("manifest blender_version_min %r must be X.Y.Z" % man["blender_version_min"])
    if not (isinstance(man["license"], list) and man["license"]
            and all(isinstance(x, str) and x.startswith("SPDX:") for x in man["license"])):
        errors.append("manifest license must be a list of \"SPDX:...\" strings")
    for p in man.get("platforms", []):
        if p not in KNOWN_PLATFORMS:
            errors.append("manifest platform %r is not one of %s" % (p, sorted(KNOWN_PLATFORMS)))
    perms = man.get("permissions", {})
    if not isinstance(perms, dict):
        errors.append("manifest [permissions] must be a table of reasons (Blender 4.2 format)")
    else:
        for k, v in perms.items():
            if k not in KNOWN_PERMISSIONS:
                errors.append("manifest permission %r is not one of %s"
                              % (k, sorted(KNOWN_PERMISSIONS)))
            check_terse("manifest permission reason for %s" % k, v, errors)

    init = os.path.join(ROOT, "addon", "__init__.py")
    bl_info = literal_assignment(init, "bl_info")
    if m:
        version = tuple(int(x) for x in m.groups())
        if tuple(bl_info.get("version", ())) != version:
            errors.append("addon/__init__.py bl_info version %r != manifest version %s"
                          % (bl_info.get("version"), man["version"]))
    for bl_key, man_key in (("name", "name"), ("description", "tagline"),
                            ("author", "maintainer")):
        if bl_info.get(bl_key) != man[man_key]:
            errors.append("addon/__init__.py bl_info %s %r != manifest %s %r"
                          % (bl_key, bl_info.get(bl_key), man_key, man[man_key]))
    native_init = os.path.join(ROOT, "native", "python", "deformkit", "__init__.py")
    native_version = literal_assignment(native_init, "__version__")
    if native_version != man["version"]:
        errors.append("native/python/deformkit/__init__.py __version__ %r != manifest version %s"
                      % (native_version, man["version"]))
    with open(os.path.join(ROOT, "CMakeLists.txt"), encoding="utf-8") as f:
        cm = re.search(r"project\(\s*DeformKit\s+VERSION\s+([0-9.]+)", f.read())
    if not cm or cm.group(1) != man["version"]:
        errors.append("CMakeLists.txt project VERSION %s != manifest version %s"
                      % (cm.group(1) if cm else "(not found)", man["version"]))
    if errors:
        raise PackageError("metadata disagrees with blender_manifest.toml (the source of "
                           "truth):\n  " + "\n  ".join(errors))
    return man


def host_platform():
    machine = platform.machine().lower()
    if sys.platform.startswith("linux") and machine in ("x86_64", "amd64"):
        return "linux-x64"
    raise PackageError("packaging is implemented for linux-x64 only (this is %s %s)"
                       % (sys.platform, machine))


# ------------------------------------------------------------------------------ ELF ----

def elf_dynamic(path):
    """(soname, [needed], runpath-or-None, rpath-or-None) from readelf -d."""
    out = run(["readelf", "-dW", path])
    soname, needed, runpath, rpath = None, [], None, None
    for line in out.splitlines():
        v = re.search(r"\[(.*)\]", line)
        if not v:
            continue
        if "(NEEDED)" in line:
            needed.append(v.group(1))
        elif "(SONAME)" in line:
            soname = v.group(1)
        elif "(RUNPATH)" in line:
            runpath = v.group(1)
        elif "(RPATH)" in line:
            rpath = v.group(1)
    return soname, needed, runpath, rpath


def ldd(path, env=None):
    """{soname: resolved path or None} for the whole dependency closure."""
    out = run(["ldd", path], env=env)
    deps = {}
    for line in out.splitlines():
        line = line.strip()
        m = re.match(r"(\S+) => (not found|(\S+) \(0x[0-9a-f]+\))", line)
        if m:
            deps[m.group(1)] = None if m.group(2) == "not found" else m.group(3)
            continue
        m = re.match(r"(\S+) \(0x[0-9a-f]+\)", line)
        if m:
            deps[os.path.basename(m.group(1))] = m.group(1)
    return deps


def glibc_needed(paths):
    """Highest GLIBC_x.y symbol version the files require."""
    best = (0, 0)
    for p in paths:
        for a, b in re.findall(r"GLIBC_(\d+)\.(\d+)", run(["readelf", "-VW", p])):
            best = max(best, (int(a), int(b)))
    return "%d.%d" % best


def unique_name(soname, path):
    """libfoo.so.3 -> libfoo-<8 hex of the file's sha256>.so.3"""
    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()[:8]
    i = soname.find(".so")
    if i < 0:
        raise PackageError("unexpected library name %s" % soname)
    return "%s-%s%s" % (soname[:i], digest, soname[i:])


def debian_package(path):
    """(package, version) owning a file, or None."""
    real = os.path.realpath(path)
    for candidate in (real, re.sub(r"^/usr/", "/", real)):
        p = subprocess.run(["dpkg", "-S", candidate], capture_output=True, text=True)
        if p.returncode == 0:
            pkg = p.stdout.split(":")[0].strip()
            ver = subprocess.run(["dpkg-query", "-W", "-f=${Version}", pkg],
                                 capture_output=True, text=True).stdout.strip()
            return pkg, ver
    return None


def patch_elf(path, bundled, soname, runpath):
    """Renames SONAME and the NEEDED entries of bundled libraries and sets RUNPATH (DT_RUNPATH,
    replacing any DT_RPATH), then reads the result back. One patchelf operation per call:
    patchelf 0.14 garbles strings when --set-rpath and --replace-needed share a call."""
    old_soname, needed, old_runpath, old_rpath = elf_dynamic(path)
    if soname and old_soname != soname:
        run(["patchelf", "--set-soname", soname, path])
    for need in needed:
        if need in bundled:
            run(["patchelf", "--replace-needed", need, bundled[need][0], path])
    if old_runpath != runpath or old_rpath is not None:
        run(["patchelf", "--set-rpath", runpath, path])
    want = (soname or old_soname, [bundled[n][0] if n in bundled else n for n in needed],
            runpath, None)
    got = elf_dynamic(path)
    if got != want:
        raise PackageError("patchelf left %s as %r, expected %r" % (path, got, want))


def bundle_native(build_dir, dest):
    """Copies the native package from BUILD/python/deformkit to dest and bundles its shared
    libraries into dest/libs. Returns a list of (original soname, bundled name, source)."""
    src = os.path.join(build_dir, "python", "deformkit")
    module_src = os.path.join(src, "_native.abi3.so")
    if not os.path.isfile(module_src):
        raise PackageError("no native module at %s: build first (scripts/setup.sh or cmake "
                           "--build %s)" % (module_src, build_dir))
    if shutil.which("patchelf") is None:
        raise PackageError("patchelf not found: run scripts/setup.sh (it installs it)")
    os.makedirs(os.path.join(dest, "libs"))
    for name in sorted(os.listdir(src)):
        if name.endswith(".py"):
            shutil.copyfile(os.path.join(src, name), os.path.join(dest, name))
    module = os.path.join(dest, "_native.abi3.so")
    shutil.copyfile(module_src, module)

    env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    closure = ldd(module, env=env)
    missing = sorted(k for k, v in closure.items() if v is None)
    if missing:
        raise PackageError("the native module's libraries are not all found on this machine: "
                           + ", ".join(missing))
    bundled = {}  # soname -> (bundled file name, source path)
    for soname, path in sorted(closure.items()):
        if soname in SYSTEM_SONAMES:
            continue
        bundled[soname] = (unique_name(soname, os.path.realpath(path)), path)
    # every bundled library's own needs must be bundled or system (ldd's closure says so,
    # but check what will actually be patched)
    for soname, (new, path) in bundled.items():
        for need in elf_dynamic(os.path.realpath(path))[1]:
            if need not in bundled and need not in SYSTEM_SONAMES:
                raise PackageError("%s needs %s, which ldd did not report" % (soname, need))

    for soname, (new, path) in sorted(bundled.items()):
        out = os.path.join(dest, "libs", new)
        shutil.copyfile(os.path.realpath(path), out)
        os.chmod(out, 0o755)
        patch_elf(out, bundled, soname=new, runpath="$ORIGIN")
    patch_elf(module, bundled, soname=None, runpath="$ORIGIN/libs")
    write_notices(os.path.join(dest, "libs", "THIRD-PARTY-NOTICES.txt"), bundled)
    return [(s, n, p) for s, (n, p) in sorted(bundled.items())]


def write_notices(path, bundled):
    """Which Debian package each bundled library comes from, and those packages' copyright
    files (their licences ask for the notices to travel with the binaries)."""
    lines = ["DeformKit bundles these shared libraries, copied unchanged (except for their",
             "names, SONAME, NEEDED and RUNPATH entries) from Debian packages:", ""]
    copyrights = {}
    for soname, (new, src) in sorted(bundled.items()):
        owner = debian_package(src)
        if owner is None:
            log("warning: %s (%s) is not from a Debian package; no licence text bundled"
                % (soname, os.path.realpath(src)))
            lines.append("  %-34s %s (not from a Debian package)" % (new, soname))
            continue
        pkg, ver = owner
        lines.append("  %-34s %s from %s %s" % (new, soname, pkg, ver))
        cp = os.path.realpath(os.path.join("/usr/share/doc", pkg, "copyright"))
        if os.path.isfile(cp):
            copyrights.setdefault(cp, []).append(pkg)
        else:
            log("warning: no copyright file for %s" % pkg)
    for cp, pkgs in sorted(copyrights.items()):
        with open(cp, encoding="utf-8", errors="replace") as f:
            text = f.read()
        lines += ["", "=" * 78, "%s (%s)" % (", ".join(sorted(pkgs)), cp), "=" * 78, text]
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")


# ------------------------------------------------------------------------------ zips ---

def addon_files():
    """(relative path, absolute path) of the add-on's files: addon/ minus caches."""
    base = os.path.join(ROOT, "addon")
    out = []
    for d, dirs, files in os.walk(base):
        dirs[:] = sorted(x for x in dirs if x != "__pycache__" and not x.startswith("."))
        for f in sorted(files):
            if f.endswith((".pyc", ".pyo")) or f.startswith("."):
                continue
            p = os.path.join(d, f)
            out.append((os.path.relpath(p, base).replace(os.sep, "/"), p))
    if not any(rel == "__init__.py" for rel, _ in out):
        raise PackageError("addon/__init__.py missing")
    return out


def tree_files(base):
    out = []
    for d, dirs, files in os.walk(base):
        dirs.sort()
        for f in sorted(files):
            p = os.path.join(d, f)
            out.append((os.path.relpath(p, base).replace(os.sep, "/"), p))
    return out


def zip_timestamp():
    """The last commit's time (zips do not change when nothing was committed), else now."""
    p = subprocess.run(["git", "-C", ROOT, "log", "-1", "--format=%ct"], capture_output=True,
                       text=True)
    t = int(p.stdout.strip()) if p.returncode == 0 and p.stdout.strip() else int(time.time())
    return time.gmtime(max(t, 315532800))[:6]


def write_zip(path, entries, stamp):
    """entries: (name in zip, file). Sorted, fixed timestamps, 0755 for shared libraries."""
    tmp = path + ".part"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        for arc, src in sorted(entries):
            info = zipfile.ZipInfo(arc, date_time=stamp)
            info.compress_type = zipfile.ZIP_DEFLATED
            mode = 0o755 if ".so" in os.path.basename(arc) else 0o644
            info.external_attr = (0o100000 | mode) << 16
            with open(src, "rb") as f:
                z.writestr(info, f.read(), compresslevel=9)
    os.replace(tmp, path)


# ---------------------------------------------------------------------------- checks ---

CHECK_SCRIPT = r'''
import os, sys
sys.modules["numpy"] = None   # memoryview outputs: no other BLAS enters the process
parent = sys.argv[1]
system_copies = set(sys.argv[2:])   # the files the bundled libraries were copied from
sys.path.insert(0, parent)
import deformkit as dk
assert os.path.realpath(dk.__file__).startswith(os.path.realpath(parent) + os.sep), dk.__file__
nx, ny = 8, 5
verts = [(i / (nx - 1), j / (ny - 1), 0.05 * ((i * j) % 3)) for j in range(ny) for i in range(nx)]
tris = []
for j in range(ny - 1):
    for i in range(nx - 1):
        a = j * nx + i
        tris += [(a, a + 1, a + nx + 1), (a, a + nx + 1, a + nx)]
mesh = dk.Mesh(verts, tris)
fixed = [j * nx for j in range(ny)]
handle = [j * nx + nx - 1 for j in range(ny)]
T = [[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.3], [0, 0, 0, 1]]]
for cls in (dk.ARAP, dk.LaplacianEdit):                 # CHOLMOD + BLAS
    r = cls(mesh, handles=[handle], fixed=fixed).solve(transforms=T)
    p = r.positions
    assert abs(p[handle[0], 2] - (verts[handle[0]][2] + 0.3)) < 1e-6, (cls, p[handle[0], 2])
    assert abs(p[fixed[0], 2] - verts[fixed[0]][2]) < 1e-9
evals, evecs = dk.laplacian_eigenpairs(mesh, 3)        # ARPACK (+ LAPACK inside it)
assert abs(evals[0]) < 1e-6 and evals[1] > 1e-3, list(evals)
R = dk.closest_rotation([[0, -2, 0], [2, 0, 0], [0, 0, 2]])  # LAPACKE SVD
assert abs(R[0, 1] + 1) < 1e-9 and abs(R[1, 0] - 1) < 1e-9, R.tolist()
libs = os.path.join(os.path.realpath(os.path.dirname(dk.__file__)), "libs")
bundled = {f for f in os.listdir(libs) if ".so" in f}
mapped = set()
with open("/proc/self/maps") as f:
    for line in f:
        parts = line.split(None, 5)
        if len(parts) == 6 and parts[5].startswith("/"):
            mapped.add(os.path.realpath(parts[5].strip()))
missing = sorted(b for b in bundled if os.path.join(libs, b) not in mapped)
assert not missing, "bundled libraries not loaded: %s" % missing
foreign = sorted(mapped & system_copies)
assert not foreign, "system copies of bundled libraries loaded: %s" % foreign
print("module check ok: %d bundled libraries mapped, none from the system" % len(bundled))
'''


def hide_prefix(paths):
    """A command prefix running in a private mount namespace with each of `paths` covered by
    /dev/null, or None if this machine allows no mount namespace."""
    if shutil.which("unshare") is None:
        return None
    for flags in (["-m"], ["-r", "-m"]):
        p = subprocess.run(["unshare", *flags, "--propagation", "private", "true"],
                           capture_output=True)
        if p.returncode == 0:
            mounts = " && ".join("mount --bind /dev/null '%s'" % x for x in paths)
            return ["unshare", *flags, "--propagation", "private", "sh", "-c",
                    mounts + ' && exec "$@"', "sh"]
    return None


def check_module(parent, bundled, python):
    """Loads the extracted module (parent/deformkit) in a fresh `python`."""
    module = os.path.join(parent, "deformkit", "_native.abi3.so")
    libs = os.path.join(parent, "deformkit", "libs")
    soname, needed, runpath, rpath = elf_dynamic(module)
    if runpath != "$ORIGIN/libs" or rpath:
        raise PackageError("module RUNPATH is %r (RPATH %r), expected $ORIGIN/libs"
                           % (runpath, rpath))
    names = {n for _, n, _ in bundled}
    for f in [module] + [os.path.join(libs, n) for n in sorted(names)]:
        for need in elf_dynamic(f)[1]:
            if need not in names and need not in SYSTEM_SONAMES:
                raise PackageError("%s still needs %s from the system" % (f, need))
    env = {k: v for k, v in os.environ.items() if not k.startswith("LD_")}
    for soname, path in ldd(module, env=env).items():
        if soname in SYSTEM_SONAMES:
            continue
        if path is None or os.path.dirname(os.path.realpath(path)) != os.path.realpath(libs):
            raise PackageError("ldd resolves %s to %s, not into %s" % (soname, path, libs))
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(CHECK_SCRIPT)
        script = f.name
    try:
        system_copies = sorted({os.path.realpath(p) for _, _, p in bundled})
        cmd = [python, "-I", script, parent] + system_copies
        prefix = hide_prefix(system_copies)
        if prefix:
            p = subprocess.run(prefix + cmd, capture_output=True, text=True, env=env)
            where = "with the %d system copies of the bundled libraries hidden" % len(
                system_copies)
        else:
            p = subprocess.run(cmd, capture_output=True, text=True, env=env)
            where = "(no mount namespace here: system copies not hidden, /proc/self/maps only)"
        if p.returncode != 0:
            raise PackageError("the extracted module fails %s:\n%s%s"
                               % (where, p.stdout, p.stderr))
        log("%s %s" % (p.stdout.strip(), where))
    finally:
        os.unlink(script)


def check_zip_layout(path, kind, man):
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        bad = z.testzip()
    if bad:
        raise PackageError("%s: corrupt member %s" % (path, bad))
    top = "" if kind == "extension" else man["id"] + "/"
    want = [top + "__init__.py", top + "deformkit/__init__.py", top + "deformkit/_native.abi3.so",
            top + "deformkit/libs/THIRD-PARTY-NOTICES.txt"]
    if kind == "extension":
        want.append("blender_manifest.toml")
    lost = [w for w in want if w not in names]
    if lost:
        raise PackageError("%s lacks %s" % (path, ", ".join(lost)))
    if kind == "legacy":
        outside = sorted(n for n in names if not n.startswith(top))
        if outside:
            raise PackageError("%s: files outside %s: %s" % (path, top, outside[:5]))
        if top + "blender_manifest.toml" in names:
            raise PackageError("%s: a manifest would make Blender 4.2 treat it as an "
                               "extension" % path)


def blender_validate(path):
    """`blender --command extension validate` where the installed Blender has it."""
    blender = shutil.which("blender")
    if not blender:
        log("note: no blender on PATH: extension validate skipped")
        return
    p = subprocess.run([blender, "--version"], capture_output=True, text=True)
    m = re.search(r"Blender (\d+)\.(\d+)(?:\.(\d+))?", p.stdout)
    if not m:
        log("note: could not read the Blender version: extension validate skipped")
        return
    ver = tuple(int(x or 0) for x in m.groups())
    if ver < (4, 2):
        log("note: Blender %d.%d.%d has no `--command extension validate` (4.2+): skipped; "
            "the manifest passed this script's own checks of the 4.2 rules" % ver)
        return
    p = subprocess.run([blender, "--factory-startup", "--command", "extension", "validate",
                        path], capture_output=True, text=True)
    if p.returncode != 0:
        raise PackageError("blender extension validate %s failed:\n%s%s"
                           % (path, p.stdout, p.stderr))
    log("blender %d.%d.%d extension validate: ok" % ver)


# ------------------------------------------------------------------------------ main ---

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build-dir", default=os.path.join(ROOT, "build"))
    ap.add_argument("--out", default=os.path.join(ROOT, "dist"))
    ap.add_argument("--python", default="/usr/bin/python3",
                    help="Python >= 3.11 used to import the extracted module")
    args = ap.parse_args(argv)
    try:
        man = read_metadata()
        plat = host_platform()
        if man.get("platforms") and plat not in man["platforms"]:
            raise PackageError("manifest platforms %s do not include %s, the platform built "
                               "here" % (man["platforms"], plat))
        tag = plat.replace("-", "_")
        os.makedirs(args.out, exist_ok=True)
        ext_zip = os.path.join(args.out, "%s-%s-%s.zip" % (man["id"], man["version"], tag))
        legacy_zip = os.path.join(args.out, "%s-%s-legacy-%s.zip"
                                  % (man["id"], man["version"], tag))
        stamp = zip_timestamp()
        with tempfile.TemporaryDirectory(prefix="deformkit-package-") as tmp:
            native_dir = os.path.join(tmp, "native", "deformkit")
            bundled = bundle_native(os.path.abspath(args.build_dir), native_dir)
            total = sum(os.path.getsize(os.path.join(native_dir, "libs", n))
                        for _, n, _ in bundled)
            log("bundled %d libraries (%.1f MB): %s" % (
                len(bundled), total / 1e6, ", ".join(s for s, _, _ in bundled)))
            elves = [os.path.join(native_dir, "_native.abi3.so")] + [
                os.path.join(native_dir, "libs", n) for _, n, _ in bundled]
            log("the bundle needs glibc >= %s" % glibc_needed(elves))
            files = addon_files()
            native = [("deformkit/" + rel, p) for rel, p in tree_files(native_dir)]
            clash = {rel for rel, _ in files} & {rel for rel, _ in native}
            if clash:
                raise PackageError("addon/ has files where the native package goes: %s" % clash)
            write_zip(ext_zip, files + native + [
                ("blender_manifest.toml", os.path.join(ROOT, "blender_manifest.toml"))], stamp)
            top = man["id"] + "/"
            write_zip(legacy_zip, [(top + rel, p) for rel, p in files + native], stamp)
            for path, kind in ((ext_zip, "extension"), (legacy_zip, "legacy")):
                check_zip_layout(path, kind, man)
                x = os.path.join(tmp, "x-" + kind)
                with zipfile.ZipFile(path) as z:
                    z.extractall(x)
                check_module(x if kind == "extension" else os.path.join(x, man["id"]),
                             bundled, args.python)
            blender_validate(ext_zip)
        for path in (ext_zip, legacy_zip):
            log("wrote %s (%.1f MB)" % (os.path.relpath(path, os.getcwd()),
                                        os.path.getsize(path) / 1e6))
    except PackageError as e:
        print("package: error: " + textwrap.indent(str(e), "  ").lstrip(), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

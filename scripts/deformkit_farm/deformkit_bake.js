// DeformKit bake: a Flamenco 3 custom job type (put this file in the Manager's `scripts`
// folder; see docs/farm.md). It splits a DeformKit point-cache bake in chunks as
// scripts/farm_bake.py does (scripts/deformkit_farm/plan.py: chunks of chunk_size
// consecutive frames, the last one shorter; a simulation's chunks each after the one before,
// continuing from its checkpoint), runs each chunk with scripts/batch_bake.py in the Worker's
// Blender (the DeformKit add-on installed there), and joins the chunks with
// batch_bake.py --join after the last one. scripts/farm_bake.py --jobs flamenco writes the
// job to submit (flamenco_job.json) with these settings filled in.
//
// Checked with Node against the Python plan (tests/farm); not yet run on a real Manager.

const JOB_TYPE = {
    label: "DeformKit Bake",
    description: "Bake a DeformKit deformer to a point cache (.pc2), in chunks",
    settings: [
        { key: "blendfile", type: "string", subtype: "file_path", required: true,
          description: "The .blend to bake (a path every Worker sees)" },
        { key: "scene", type: "string", required: true, description: "Scene to bake in" },
        { key: "object", type: "string", required: true,
          description: "The deformed mesh object" },
        { key: "deformer", type: "string", required: true, description: "Its DeformKit deformer" },
        { key: "frames", type: "string", required: true,
          description: "Frame range A-B (inclusive)" },
        { key: "chunk_size", type: "int32", default: 12, description: "Frames per task" },
        { key: "simulation", type: "bool", default: false,
          description: "The deformer is a simulation (farm_bake.py --jobs says): chunks in order" },
        { key: "output_cache", type: "string", subtype: "file_path", required: true,
          description: "The joined point cache" },
        { key: "chunk_folder", type: "string", subtype: "dir_path", required: true,
          description: "The chunks' caches and checkpoints (shared storage)" },
        { key: "batch_script", type: "string", subtype: "file_path", required: true,
          description: "scripts/batch_bake.py as the Workers see it" },
    ],
};

function deformkitPlan(frames, chunkSize, simulation) {
    const m = /^\s*(-?\d+)\s*-\s*(-?\d+)\s*$/.exec(frames) || /^\s*(-?\d+)\s*$/.exec(frames);
    if (!m) throw `frames must look like A-B, got "${frames}"`;
    const first = parseInt(m[1], 10);
    const last = m[2] === undefined ? first : parseInt(m[2], 10);
    if (last < first) throw `empty frame range ${first}-${last}`;
    if (!(chunkSize >= 1)) throw `a chunk is at least 1 frame, got ${chunkSize}`;
    const chunks = [];
    for (let a = first, i = 0; a <= last; a += chunkSize, i++) {
        chunks.push({ index: i, first: a, last: Math.min(a + chunkSize - 1, last),
                      after: simulation && i > 0 ? i - 1 : -1 });
    }
    return chunks;
}

function deformkitChunkCache(folder, c) {
    return `${folder}/chunk_${c.first}_${c.last}.pc2`;
}

function compileJob(job) {
    const s = job.settings;
    const plan = deformkitPlan(s.frames, s.chunk_size, s.simulation);
    const target = ["--scene", s.scene, "--python-exit-code", "1", "--python", s.batch_script,
                    "--", "--object", s.object, "--deformer", s.deformer];
    const tasks = [];
    for (const c of plan) {
        // --frames=A-B in one word: a range starting below zero ("-5-6") is not an option
        const args = target.concat([`--frames=${c.first}-${c.last}`,
                                    "--out", deformkitChunkCache(s.chunk_folder, c)]);
        if (s.simulation) args.push("--checkpoints", s.chunk_folder);
        const task = author.Task(`bake-${c.first}-${c.last}`, "blender");
        task.addCommand(author.Command("blender-render", {
            exe: "{blender}", exeArgs: "{blenderArgs}", argsBefore: [],
            blendfile: s.blendfile, args: args }));
        if (c.after >= 0) task.addDependency(tasks[c.after]);
        job.addTask(task);
        tasks.push(task);
    }
    const join = author.Task("join", "blender");
    join.addCommand(author.Command("blender-render", {
        exe: "{blender}", exeArgs: "{blenderArgs}", argsBefore: [], blendfile: s.blendfile,
        args: ["--python-exit-code", "1", "--python", s.batch_script, "--", "--join"]
            .concat(plan.map(c => deformkitChunkCache(s.chunk_folder, c)))
            .concat(["--out", s.output_cache]) }));
    for (const t of tasks) join.addDependency(t);
    job.addTask(join);
}

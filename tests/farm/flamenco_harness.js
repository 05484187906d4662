// Runs a Flamenco job type's compileJob(job) outside a Manager, with the Manager's `author`
// API stood in for by plain objects, and prints the tasks it made as JSON:
//   node flamenco_harness.js JOB_TYPE.js JOB.json
// (tests/farm/test_farm.py compares them with scripts/deformkit_farm's Python plan).
"use strict";
const fs = require("fs");
const vm = require("vm");
const [script, jobPath] = process.argv.slice(2);
const tasks = [];
const author = {
    Task: (name, type) => ({
        name, type, commands: [], dependencies: [],
        addCommand(c) { this.commands.push(c); },
        addDependency(t) { this.dependencies.push(t.name); },
    }),
    Command: (name, parameters) => ({ name, parameters }),
};
const job = JSON.parse(fs.readFileSync(jobPath, "utf8"));
job.addTask = (t) => tasks.push(t);
const context = vm.createContext({ author, job });
vm.runInContext(fs.readFileSync(script, "utf8"), context, { filename: script });
vm.runInContext("compileJob(job)", context);
const type = vm.runInContext("JOB_TYPE", context);
process.stdout.write(JSON.stringify({
    label: type.label, settings: type.settings.map((s) => s.key),
    tasks: tasks.map(({ name, type, commands, dependencies }) => ({ name, type, commands, dependencies })),
}) + "\n");

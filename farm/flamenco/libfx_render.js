// Flamenco 3 job type: render a frame range in chunks through libfx's batch runner
// (addon/libfx/batch.py), so every frame gets Blender's render *and* the scene's libfx
// effect stack. Put this file in the `scripts/` folder next to the flamenco-manager
// executable and restart the Manager; see docs/farm.md.
//
// One task per chunk; each runs
//   {blender} {blenderArgs} --factory-startup FILE.blend --python-exit-code 2 \
//       --python {libfx_addon}/batch.py -- --frames CHUNK --output PREFIX --skip-existing [...]
// The runner exits 0 when every frame of the chunk has its result, 1 when a frame's
// stack failed, 2 on a usage/setup error, so Flamenco marks the task failed and can
// re-queue it; --skip-existing makes the re-run render only the frames still missing.
// A last task, libfx-check, runs once every chunk has succeeded: the runner's own
// completeness check over the whole range (`batch.py --check`), which also writes the
// shot's contact sheet, <prefix>libfx.contact_sheet.png (the Slurm submitter's final job
// runs the same command: farm/slurm/libfx_slurm.py).
//
// Globals provided by the Manager's job compiler: author, path, frameChunker, print.

const LIBFX_QUALITIES = ["scene", "draft", "preview", "final", "reference"];

const JOB_TYPE = {
    label: "libfx Render (batch runner)",
    description: "Render frames with Blender and apply the scene's libfx effect stack, in chunks",
    settings: [
        // What to render.
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
          evalInfo: { showLinkButton: true, description: "The scene's frame range" },
          description: "Frames, e.g. '1-250' or '1-10,20,31-40'" },
        { key: "chunk_size", type: "int32", default: 10, propargs: { min: 1, max: 1000 },
          description: "Frames per task: Blender and the add-on start once per chunk (docs/farm.md)" },

        // Where results go: one stable folder per job name, so a re-submitted job
        // skips the frames it already finished.
        { key: "output_root", type: "string", subtype: "dir_path", required: true, visible: "submission",
          description: "Folder on shared storage that every worker can write" },
        { key: "output_prefix", type: "string", subtype: "file_path", editable: false,
          eval: "str(Path(abspath(settings.output_root), jobname, jobname + '_'))",
          description: "libfx writes <prefix>libfx.####.exr (and Blender's own <prefix>####.ext)" },

        // Overrides; empty or 0 keeps the scene's value.
        { key: "resolution", type: "string", default: "", visible: "submission",
          description: "WxH at 100%, e.g. 1920x1080; empty: the scene's" },
        { key: "samples", type: "int32", default: 0, propargs: { min: 0 }, visible: "submission",
          description: "Render samples; 0: the scene's" },
        { key: "quality", type: "string", default: "scene", choices: LIBFX_QUALITIES, visible: "submission",
          description: "libfx quality preset; 'scene': the stack's own" },
        { key: "recipe", type: "string", subtype: "file_path", default: "", visible: "submission",
          description: "Recipe .json replacing the scene's stack (a path the workers see); empty: the scene's" },
        { key: "threads", type: "int32", default: 0, propargs: { min: 0 }, visible: "submission",
          description: "libfx worker threads; 0: one per core" },
        { key: "skip_existing", type: "bool", default: true, visible: "submission",
          description: "Skip frames whose complete result exists (re-queued chunks, re-submitted jobs)" },

        // Where the add-on is on the workers: a Manager variable by default, so each
        // platform can have its own path (flamenco-manager.yaml, `variables:`).
        { key: "addon_dir", type: "string", default: "{libfx_addon}", visible: "visible",
          description: "The libfx add-on folder on the workers (the one holding batch.py and lib/)" },
        { key: "factory_startup", type: "bool", default: true, visible: "visible",
          description: "Ignore the workers' Blender preferences, so the add-on in addon_dir is the one that runs" },

        // Filled in by the Flamenco add-on on submission.
        { key: "blendfile", type: "string", required: true, visible: "web",
          description: "The .blend file to render (as the workers see it)" },
    ],
};

function compileJob(job) {
    const settings = job.settings;
    checkSettings(settings);
    const chunks = frameChunker(settings.frames, settings.chunk_size);
    const chunkTasks = chunks.map((chunk) => libfxChunkTask(settings, chunk));
    for (const task of chunkTasks) {
        job.addTask(task);
    }
    const check = libfxCheckTask(settings, chunks.join(","));
    for (const task of chunkTasks) {
        check.addDependency(task);
    }
    job.addTask(check);
    print(`libfx: ${chunks.length} chunk(s) of at most ${settings.chunk_size} frame(s), then libfx-check`);
}

// Rejects settings that would make every task fail, at submission instead.
function checkSettings(settings) {
    if (!settings.blendfile) {
        throw "libfx: no blendfile setting";
    }
    if (!settings.output_prefix) {
        throw "libfx: no output_prefix setting (set output_root)";
    }
    if (settings.resolution && !/^[1-9][0-9]*x[1-9][0-9]*$/.test(settings.resolution)) {
        throw `libfx: resolution must be WxH (e.g. 1920x1080), not "${settings.resolution}"`;
    }
    if (settings.quality && LIBFX_QUALITIES.indexOf(settings.quality) < 0) {
        throw `libfx: quality must be one of ${LIBFX_QUALITIES.join(", ")}`;
    }
}

// The batch runner's arguments for one chunk (after `--`).
function libfxRunnerArgs(settings, chunk) {
    const args = ["--frames", chunk, "--output", settings.output_prefix];
    if (settings.skip_existing !== false) args.push("--skip-existing");
    if (settings.resolution) args.push("--resolution", settings.resolution);
    if (settings.samples > 0) args.push("--samples", String(settings.samples));
    if (settings.quality && settings.quality !== "scene") args.push("--quality", settings.quality);
    if (settings.recipe) args.push("--recipe", settings.recipe);
    if (settings.threads > 0) args.push("--threads", String(settings.threads));
    return args;
}

function libfxChunkTask(settings, chunk) {
    return libfxRunnerTask(settings, `libfx-${chunk}`, libfxRunnerArgs(settings, chunk));
}

// Every frame of the job has a complete result (the runner decides, reading each back),
// then the contact sheet; exit 1 names each frame that has not.
function libfxCheckTask(settings, frames) {
    return libfxRunnerTask(settings, "libfx-check", [
        "--check", "--frames", frames, "--output", settings.output_prefix,
        "--contact-sheet", settings.output_prefix + "libfx.contact_sheet.png"]);
}

function libfxRunnerTask(settings, name, runnerArgs) {
    const task = author.Task(name, "blender");
    const addonDir = settings.addon_dir || "{libfx_addon}";
    const command = author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: settings.factory_startup === false ? [] : ["--factory-startup"],
        blendfile: settings.blendfile,
        // --python-exit-code: a runner that cannot even be opened (wrong addon_dir)
        // must fail the task; Blender would otherwise exit 0.
        args: ["--python-exit-code", "2", "--python", path.join(addonDir, "batch.py"), "--"]
            .concat(runnerArgs),
    });
    task.addCommand(command);
    return task;
}

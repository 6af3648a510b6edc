// HumanAnim batch pipeline as a Flamenco job type (Flamenco 3: copy this file into the Manager's
// scripts/ folder and restart it). One Flamenco task per take; the task runs the pipeline's steps
// one after the other with the farm's Blender, exactly as `python -m humananim batch` does:
//
//   {blender} --command humananim control TAKE.bvh --load-left 5 --out OUT/TAKE/1-control.blend --json
//   {blender} --command humananim compress OUT/TAKE/1-control.blend --degrees 0.5 --out OUT/TAKE/2-compress.blend --json
//
// The take folders and file names are the batch's own (docs/batch.md). Flamenco schedules, retries
// and reports the tasks, so no Dask is needed on the farm: only the HumanAnim extension installed
// in the workers' Blender and the takes and the output folder on storage every worker sees.

const JOB_TYPE = {
  label: "HumanAnim Batch",
  description: "Run a HumanAnim pipeline (e.g. control -> compress) over many motion takes",
  settings: [
    { key: "takes", type: "string", required: true,
      description: "Motion files (.bvh or .blend) on shared storage, one per line or separated by ';'" },
    { key: "pipeline", type: "string", required: true, default: "control --load-left 5 -> compress --degrees 0.5",
      description: "HumanAnim commands separated by '->'; each reads what the previous one wrote" },
    { key: "out_dir", type: "string", subtype: "dir_path", required: true,
      description: "Output folder on shared storage: one folder per take" },
    { key: "blender_args", type: "string", default: "",
      description: "Extra Blender options before --command (e.g. --python-exit-code 1)" },
  ],
};

// Commands that read a file but write none: the next step reads the same file.
const WRITES_NOTHING = ["info"];

function compileJob(job) {
  const settings = job.settings;
  const steps = parsePipeline(settings.pipeline);
  const takes = splitTakes(settings.takes);
  if (takes.length == 0) {
    throw new Error("no takes: list the motion files, one per line");
  }
  const before = shellWords(settings.blender_args || "");
  const used = {};
  for (const file of takes) {
    const name = takeName(file, used);
    const folder = joinPath(settings.out_dir, name);
    const task = author.Task("humananim-" + name, "blender");
    let current = file;
    steps.forEach(function (step, i) {
      const args = before.concat(["--command", "humananim", step.command, current]).concat(step.args);
      if (WRITES_NOTHING.indexOf(step.command) < 0) {
        const out = joinPath(folder, (i + 1) + "-" + step.command + ".blend");
        args.push("--out", out);
        current = out;
      }
      args.push("--json");
      task.addCommand(author.Command("exec", { exe: "{blender}", args: args }));
    });
    job.addTask(task);
  }
}

// "a --x 1 -> b" -> [{command: "a", args: ["--x", "1"]}, {command: "b", args: []}]
function parsePipeline(text) {
  const steps = [];
  for (const part of String(text || "").split(/\s*(?:->|=>)\s*/)) {
    const words = shellWords(part);
    if (words.length == 0) {
      continue;
    }
    if (words.indexOf("--out") >= 0 || words.indexOf("--json") >= 0) {
      throw new Error("pipeline step '" + words[0] + "': the job sets --out and --json itself");
    }
    steps.push({ command: words[0], args: words.slice(1) });
  }
  if (steps.length == 0) {
    throw new Error("the pipeline is empty");
  }
  return steps;
}

// Words as a POSIX shell splits them (single and double quotes, backslash escapes).
function shellWords(text) {
  const words = [];
  let word = null;
  let quote = null;
  for (let i = 0; i < text.length; i++) {
    const c = text[i];
    if (quote) {
      if (c == quote) {
        quote = null;
      } else if (c == "\\" && quote == '"' && i + 1 < text.length) {
        word += text[++i];
      } else {
        word += c;
      }
    } else if (c == "'" || c == '"') {
      quote = c;
      word = word || "";
    } else if (c == "\\" && i + 1 < text.length) {
      word = (word || "") + text[++i];
    } else if (/\s/.test(c)) {
      if (word !== null) {
        words.push(word);
        word = null;
      }
    } else {
      word = (word || "") + c;
    }
  }
  if (quote) {
    throw new Error("unclosed quote in: " + text);
  }
  if (word !== null) {
    words.push(word);
  }
  return words;
}

function splitTakes(text) {
  return String(text || "").split(/[\n;]/).map(function (s) { return s.trim(); }).filter(function (s) { return s.length > 0; });
}

// The batch's take folder name: the file's stem made safe, -2, -3 ... on repeats.
function takeName(file, used) {
  const base = file.split(/[\\/]/).pop();
  const dot = base.lastIndexOf(".");
  let stem = (dot > 0 ? base.slice(0, dot) : base).replace(/[^A-Za-z0-9._-]+/g, "_").replace(/^[._]+|[._]+$/g, "");
  stem = stem || "take";
  let name = stem;
  for (let n = 2; used[name]; n++) {
    name = stem + "-" + n;
  }
  used[name] = true;
  return name;
}

function joinPath(folder, name) {
  return folder.replace(/[\\/]+$/, "") + "/" + name;
}

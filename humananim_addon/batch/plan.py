"""Planning a batch: which takes (a folder, a glob or a manifest), which pipeline of commands,
each take's command lines, the hash of its options and whether its outputs are already complete.

No bpy and no dask here: the planner runs in the driver, in tests and in the Blender panel.

A pipeline is a list of steps, each a registered command with its options, e.g.
``control --load-left 5 -> compress --degrees 0.5``. The batch gives every step the take's
current file as its positional argument and its own ``--out`` in the take's folder; the next
step reads what the previous one wrote. Per-take options come from the manifest: a column (CSV)
or key (JSON) ``control.load-left`` goes to the control step, a plain ``frames`` to every step
that has a ``--frames`` option.
"""

import contextlib
import csv
import dataclasses
import glob
import hashlib
import io
import json
import os
import re
import shlex

INPUT_SUFFIXES = (".bvh", ".fbx", ".blend")
RECORD = "take.json"  # written last, atomically, into a finished take's folder
PARTIAL = ".partial"  # takes being written: renamed into place when finished
FORMAT = 1  # bump when the layout of a take's folder changes: every take is redone


class PlanError(Exception):
    """A mistake in the batch's inputs, pipeline or manifest (one line, exit status 2)."""


@dataclasses.dataclass
class Step:
    command: str
    args: list  # the options as given, without the file, --out and --json

    def __str__(self):
        return " ".join([self.command] + [shlex.quote(a) for a in self.args])


@dataclasses.dataclass
class Take:
    name: str
    file: str  # absolute
    options: dict = dataclasses.field(default_factory=dict)  # manifest options: {key: value}
    steps: list = dataclasses.field(default_factory=list)  # [[command, arg, ...]] without file/--out
    options_hash: str = ""

    def folder(self, out_dir):
        return os.path.join(out_dir, self.name)

    def to_dict(self):
        return dataclasses.asdict(self)


def parse_pipeline(texts):
    """Steps from `--pipeline "a --x 1 -> b"` texts and/or `--step "a --x 1"` texts."""
    steps = []
    for text in texts:
        for part in re.split(r"\s*(?:->|=>)\s*", text.strip()):
            if not part:
                continue
            words = shlex.split(part)
            steps.append(Step(words[0], words[1:]))
    if not steps:
        raise PlanError("the pipeline is empty: give --pipeline 'COMMAND [OPTIONS] -> ...' or --step")
    return steps


def find_inputs(sources):
    """Files from folders (their .bvh/.fbx/.blend files), globs and plain paths, sorted, no repeats.
    A manifest (.csv/.json) is read with `read_manifest` instead."""
    files = []
    for source in sources:
        if os.path.isdir(source):
            found = [os.path.join(source, f) for f in sorted(os.listdir(source))
                     if f.lower().endswith(INPUT_SUFFIXES)]
        elif any(c in source for c in "*?["):
            found = sorted(glob.glob(source, recursive=True))
        else:
            found = [source]  # a missing file becomes a failed take, reported like a broken one
        if not found:
            raise PlanError(f"no .bvh, .fbx or .blend files in {source!r}")
        files += found
    seen, unique = set(), []
    for f in files:
        f = os.path.abspath(f)
        if f not in seen:
            seen.add(f)
            unique.append(f)
    return unique


def read_manifest(path):
    """[(file, name or None, options)] from a CSV (a `file` column; `name`; any other column is an
    option) or a JSON list of objects (or {"takes": [...]}) with the same keys. Relative files are
    relative to the manifest's folder. Empty cells and null values set nothing."""
    base = os.path.dirname(os.path.abspath(path))
    try:
        with open(path, newline="", encoding="utf-8") as f:
            if path.lower().endswith(".json"):
                data = json.load(f)
                rows = data.get("takes") if isinstance(data, dict) else data
                if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
                    raise PlanError(f"{os.path.basename(path)}: expected a list of objects (or {{\"takes\": [...]}})")
            else:
                rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, csv.Error) as error:
        raise PlanError(f"cannot read manifest {os.path.basename(path)}: {error}") from None
    takes = []
    for i, row in enumerate(rows, start=2 if not path.lower().endswith(".json") else 1):
        row = {str(k).strip(): v for k, v in row.items() if k is not None}
        file = row.pop("file", None)
        if not file:
            raise PlanError(f"{os.path.basename(path)}: take {i} has no 'file'")
        name = row.pop("name", None) or None
        options = {k: v for k, v in row.items() if v not in (None, "")}
        takes.append((os.path.normpath(os.path.join(base, str(file))), name, options))
    if not takes:
        raise PlanError(f"{os.path.basename(path)}: no takes")
    return takes


def option_words(key, value):
    """`--key value` words of a manifest option: true -> a flag, a list or "a b" -> several values."""
    flag = "--" + key.lstrip("-")
    if value is True or (isinstance(value, str) and value.strip().lower() in ("true", "yes")):
        return [flag]
    if value is False or (isinstance(value, str) and value.strip().lower() in ("false", "no")):
        return []
    if isinstance(value, (list, tuple)):
        return [flag] + [str(v) for v in value]
    if isinstance(value, str):
        return [flag] + value.split()
    return [flag, repr(value) if isinstance(value, float) else str(value)]


def take_name(file, used, name=None):
    """A folder name for the take: its manifest name or the file's stem, made safe, with -2, -3 ...
    on repeats."""
    stem = name or os.path.splitext(os.path.basename(file))[0]
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", stem).strip("._") or "take"
    name, n = stem, 2
    while name in used:
        name, n = f"{stem}-{n}", n + 1
    used.add(name)
    return name


def plan(sources, steps, parser=None):
    """The takes of a batch: [Take], each with its resolved step options and their hash.

    `sources` are folders, globs, files, or one manifest (.csv/.json). `parser` is the
    humananim argument parser (to check every step and option before anything runs)."""
    if len(sources) == 1 and sources[0].lower().endswith((".csv", ".json")):
        entries = read_manifest(sources[0])
    else:
        entries = [(f, None, {}) for f in find_inputs(sources)]
    known = step_options(parser, steps) if parser else None
    used, takes = set(), []
    for file, name, options in entries:
        take = Take(take_name(file, used, name), os.path.abspath(file), options)
        for index, step in enumerate(steps):
            words = list(step.args)
            for key, value in options.items():
                target, _, option = key.rpartition(".")
                if target and target not in (step.command, str(index + 1)):
                    continue
                if known is not None and "--" + option.lstrip("-") not in known[index]:
                    if target:
                        raise PlanError(f"take {take.name}: {step.command} has no option --{option}")
                    continue  # a plain option goes only to the steps that have it
                words += option_words(option, value)
            take.steps.append([step.command] + words)
        unused = [k for k in options if known is not None and not any(
            "--" + k.rpartition(".")[2].lstrip("-") in known[i] for i in range(len(steps)))]
        if unused:
            raise PlanError(f"take {take.name}: no step has the option{'s' if len(unused) > 1 else ''} "
                            + ", ".join("--" + k.rpartition(".")[2] for k in unused))
        take.options_hash = options_hash(take.steps)
        takes.append(take)
    return takes


def options_hash(steps):
    """The hash of what a take's outputs depend on besides its input file."""
    text = json.dumps({"format": FORMAT, "steps": steps}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def step_options(parser, steps):
    """Check every step against the command line parser: [set of option strings] per step."""
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    known = []
    for step in steps:
        command = sub.choices.get(step.command)
        if command is None or step.command == "batch":
            raise PlanError(f"unknown pipeline step {step.command!r} (commands: "
                            f"{', '.join(sorted(c for c in sub.choices if c != 'batch'))})")
        positionals = [a for a in command._actions if not a.option_strings]
        if [a.dest for a in positionals] != ["file"]:
            raise PlanError(f"pipeline step {step.command!r} does not read a file")
        for word in ("--out", "--json"):
            if word in step.args:
                raise PlanError(f"pipeline step {step.command!r}: the batch sets {word} itself")
        said = io.StringIO()
        try:
            with contextlib.redirect_stderr(said):  # argparse's usage text: one line is enough
                command.parse_args(["input.bvh"] + step.args)
        except SystemExit:
            reason = said.getvalue().strip().splitlines()[-1].split("error: ", 1)[-1] if said.getvalue().strip() else ""
            raise PlanError(f"pipeline step '{step}': {reason or 'bad options'} (see `python -m humananim "
                            f"{step.command} --help`)") from None
        known.append({s for a in command._actions for s in a.option_strings})
    return known


def is_complete(take, out_dir):
    """A take is done when its record says so for these options, every file it lists exists, and
    the record is newer than the input file."""
    folder = take.folder(out_dir)
    record = load_record(folder)
    if not record or record.get("status") != "done" or record.get("options_hash") != take.options_hash:
        return False
    if record.get("file") != take.file:
        return False
    try:
        if os.path.getmtime(os.path.join(folder, RECORD)) < os.path.getmtime(take.file):
            return False
    except OSError:
        return False
    return all(os.path.isfile(os.path.join(folder, f)) for f in record.get("outputs", []))


def load_record(folder):
    try:
        with open(os.path.join(folder, RECORD), encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def write_json_atomic(path, data):
    """Write to a temporary file in the same folder, then rename: readers never see half a file."""
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)

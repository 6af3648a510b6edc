#!/usr/bin/env python3
"""Build the HumanAnim extension zips with Blender's own extension builder.

    python .ci/build_extension.py                          # all four platforms -> build/dist
    python .ci/build_extension.py --platforms linux-x64    # one platform
    python .ci/build_extension.py --json                   # one JSON object on stdout

Steps:
1. Stage the extension's files into build/stage: the root __init__.py, blender_manifest.toml,
   every root subpackage (solver/, humananim_addon/ with its data/, operators/, panels/, ...)
   and LICENSE*/README* — never tests/, benchmarks/, .ci/, build/, pyproject.toml, __main__.py
   (`python -m humananim` is a development entry point; Blender never runs it).
2. Fetch the wheels pinned in .ci/wheels.lock into build/wheels (a cache: a file already there
   with the right sha256 is kept), through pip from the package registry with the exact tags of
   each file name and --require-hashes; check every sha256 again and fail on any mismatch; copy
   the selected platforms' wheels into build/stage/wheels/.
3. Run `blender_ext.py build --split-platforms --valid-tags=<Blender's tags.py>`, then
   `blender_ext.py validate` on each zip, and check each zip's file list.
4. Print the zips with their sizes (with --json: one JSON object).

Runs with any Python >= 3.11 that has pip; needs no bpy, only a copy of blender_ext.py (from an
installed bpy module, /tmp/venvs/*, $HUMANANIM_BLENDER_EXT or --blender-ext).
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LOCK_PATH = REPO / ".ci" / "wheels.lock"
MANIFEST_NAME = "blender_manifest.toml"
ALL_PLATFORMS = ("linux-x64", "windows-x64", "macos-arm64", "macos-x64")

# Root directories that are never part of the extension, even when they hold an __init__.py.
EXCLUDED_DIRS = {"tests", "benchmarks", "build", "out", "wheels", "dist", "docs", "scripts"}
# Root subpackages that must be staged (a missing one means a broken checkout).
REQUIRED_DIRS = ("solver", "humananim_addon", "operators", "panels")
# Root files staged besides the subpackages.
ROOT_FILES = ("__init__.py", MANIFEST_NAME)
ROOT_FILE_GLOBS = ("LICENSE*", "COPYING*", "README*")
# Never inside the zip (checked after the build).
FORBIDDEN_TOP = ("tests/", "benchmarks/", ".ci/", "build/", ".git/", "pyproject.toml", "setup.py", "__main__.py")
IGNORE_IN_TREES = shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo", ".*", "*.egg-info", "*.blend[1-9]")


class BuildError(RuntimeError):
    pass


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------
# Lock file and manifest

def load_lock(path: Path = LOCK_PATH) -> list[dict]:
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    entries = data.get("wheel", [])
    if not entries:
        raise BuildError(f"{path}: no [[wheel]] entries")
    seen = set()
    for e in entries:
        for key in ("file", "sha256", "platforms"):
            if key not in e:
                raise BuildError(f"{path}: entry {e!r} lacks {key!r}")
        if e["file"] in seen:
            raise BuildError(f"{path}: {e['file']} listed twice")
        seen.add(e["file"])
        if not re.fullmatch(r"[0-9a-f]{64}", e["sha256"]):
            raise BuildError(f"{path}: bad sha256 for {e['file']}")
        unknown = set(e["platforms"]) - set(ALL_PLATFORMS)
        if unknown:
            raise BuildError(f"{path}: {e['file']}: unknown platforms {sorted(unknown)}")
    return entries


def load_manifest(path: Path = REPO / MANIFEST_NAME) -> dict:
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def check_manifest_matches_lock(manifest: dict, lock: list[dict]) -> None:
    listed = [w.removeprefix("./").removeprefix("wheels/") for w in manifest.get("wheels", [])]
    bad_dir = [w for w in manifest.get("wheels", []) if not w.startswith("./wheels/")]
    if bad_dir:
        raise BuildError(f"manifest wheels must live in ./wheels/: {bad_dir}")
    if sorted(listed) != sorted(e["file"] for e in lock):
        raise BuildError(
            "blender_manifest.toml `wheels` differs from .ci/wheels.lock:\n"
            f"  only in manifest: {sorted(set(listed) - {e['file'] for e in lock})}\n"
            f"  only in lock:     {sorted({e['file'] for e in lock} - set(listed))}"
        )


def parse_wheel_name(filename: str) -> dict:
    parts = filename[:-len(".whl")].split("-")
    if len(parts) not in (5, 6):
        raise BuildError(f"not a wheel file name: {filename}")
    name, version = parts[0], parts[1]
    python, abi, plat = parts[-3], parts[-2], parts[-1]
    return {"name": name, "version": version, "python": python, "abi": abi, "platform": plat}


# --------------------------------------------------------------------------------------
# Finding Blender's extension tool

def _blender_ext_candidates() -> list[Path]:
    found: list[Path] = []
    spec = importlib.util.find_spec("bpy")
    roots = []
    if spec is not None and spec.submodule_search_locations:
        roots += list(spec.submodule_search_locations)
    roots += sorted(glob.glob("/tmp/venvs/*/lib/python3*/site-packages/bpy"))
    for root in roots:
        found += [Path(p) for p in glob.glob(os.path.join(root, "*", "scripts", "addons_core",
                                                          "bl_pkg", "cli", "blender_ext.py"))]
    return found


def _version_key(p: Path) -> tuple:
    # .../bpy/<X.Y>/scripts/addons_core/bl_pkg/cli/blender_ext.py
    try:
        return tuple(int(x) for x in p.parents[4].name.split("."))
    except ValueError:
        return (0,)


def find_blender_ext(explicit: str | None) -> Path:
    if explicit:
        p = Path(explicit)
        if not p.is_file():
            raise BuildError(f"--blender-ext {p} does not exist")
        return p.resolve()
    env = os.environ.get("HUMANANIM_BLENDER_EXT")
    if env:
        return find_blender_ext(env)
    cands = _blender_ext_candidates()
    if not cands:
        raise BuildError("blender_ext.py not found: install bpy (pip install bpy) or pass --blender-ext")
    # The running interpreter's bpy comes first; otherwise the newest Blender.
    return cands[0].resolve() if importlib.util.find_spec("bpy") else max(cands, key=_version_key).resolve()


def tags_file_for(blender_ext: Path) -> Path | None:
    # .../scripts/addons_core/bl_pkg/cli/blender_ext.py -> .../scripts/modules/_bpy_internal/extensions/tags.py
    p = blender_ext.parents[3] / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    return p if p.is_file() else None


# --------------------------------------------------------------------------------------
# Staging

def stage_sources(stage: Path) -> list[str]:
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    for name in ROOT_FILES:
        src = REPO / name
        if not src.is_file():
            raise BuildError(f"missing {src}")
        shutil.copy2(src, stage / name)
    for pattern in ROOT_FILE_GLOBS:
        for src in sorted(REPO.glob(pattern)):
            if src.is_file():
                shutil.copy2(src, stage / src.name)
    for name in REQUIRED_DIRS:
        if not (REPO / name / "__init__.py").is_file():
            raise BuildError(f"missing subpackage {name}/__init__.py")
    staged_dirs = []
    for sub in sorted(REPO.iterdir()):
        if (sub.is_dir() and not sub.name.startswith((".", "_")) and sub.name not in EXCLUDED_DIRS
                and not sub.name.endswith(".egg-info") and (sub / "__init__.py").is_file()):
            shutil.copytree(sub, stage / sub.name, ignore=IGNORE_IN_TREES)
            staged_dirs.append(sub.name)
    return staged_dirs


def restrict_manifest(manifest_path: Path, platforms: list[str], wheels: list[str]) -> None:
    """Rewrite `platforms` and `wheels` of the staged manifest for a subset build."""
    text = manifest_path.read_text(encoding="utf-8")

    def repl(key: str, values: list[str], text: str) -> str:
        new = key + " = [\n" + "".join(f'  "{v}",\n' for v in values) + "]"
        out, n = re.subn(rf"(?ms)^{key}\s*=\s*\[.*?\]", new, text, count=1)
        if n != 1:
            raise BuildError(f"cannot find `{key} = [...]` in {manifest_path}")
        return out

    text = repl("platforms", platforms, text)
    text = repl("wheels", wheels, text)
    manifest_path.write_text(text, encoding="utf-8")


# --------------------------------------------------------------------------------------
# Wheels

def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _pip_download_group(entries: list[dict], dest: Path) -> None:
    """One pip call for wheels sharing python/abi/platform tags; pip checks the hashes too."""
    w = parse_wheel_name(entries[0]["file"])
    with tempfile.TemporaryDirectory(dir=dest, prefix=".pip-") as tmp:
        req = Path(tmp) / "requirements.txt"
        req.write_text("".join(
            f"{e.get('project', parse_wheel_name(e['file'])['name'])}=="
            f"{e.get('version', parse_wheel_name(e['file'])['version'])} --hash=sha256:{e['sha256']}\n"
            for e in entries))
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
               "--require-hashes", "--disable-pip-version-check", "-q", "-r", str(req), "-d", tmp]
        if w["platform"] != "any":
            cmd += ["--implementation", "cp", "--abi", w["abi"],
                    "--python-version", w["python"][2] + "." + w["python"][3:]]
            for plat in w["platform"].split("."):
                cmd += ["--platform", plat]
        log("  pip download " + ", ".join(e["file"] for e in entries))
        res = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if res.returncode != 0:
            raise BuildError("pip download failed:\n  " + " ".join(cmd) + "\n" + res.stdout)
        for e in entries:
            got = Path(tmp) / e["file"]
            if not got.is_file():
                raise BuildError(f"pip did not fetch {e['file']} (got {sorted(os.listdir(tmp))})")
            digest = sha256_of(got)
            if digest != e["sha256"]:
                raise BuildError(f"SHA256 MISMATCH for {e['file']}: expected {e['sha256']}, got {digest}")
            os.replace(got, dest / e["file"])


def fetch_wheels(entries: list[dict], cache: Path) -> tuple[int, int]:
    cache.mkdir(parents=True, exist_ok=True)
    missing = []
    cached = 0
    for e in entries:
        p = cache / e["file"]
        if p.is_file():
            if sha256_of(p) == e["sha256"]:
                cached += 1
                continue
            log(f"  {e['file']}: cached copy has the wrong sha256, fetching again")
            p.unlink()
        missing.append(e)
    groups: dict[tuple, list[dict]] = {}
    for e in missing:
        w = parse_wheel_name(e["file"])
        groups.setdefault((w["python"], w["abi"], ".".join(sorted(w["platform"].split(".")))), []).append(e)
    for group in groups.values():
        _pip_download_group(group, cache)
    # Check everything once more: a cache is only as good as its last check.
    for e in entries:
        digest = sha256_of(cache / e["file"])
        if digest != e["sha256"]:
            raise BuildError(f"SHA256 MISMATCH for {e['file']}: expected {e['sha256']}, got {digest}")
    return len(missing), cached


def _link_or_copy(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


# --------------------------------------------------------------------------------------
# Build

def run_tool(cmd: list[str]) -> str:
    res = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if res.returncode != 0:
        raise BuildError("command failed (exit {}):\n  {}\n{}".format(res.returncode, " ".join(cmd), res.stdout))
    return res.stdout


def check_zip(path: Path, expected_wheels: set[str]) -> list[str]:
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    bad = [n for n in names if n.startswith(FORBIDDEN_TOP) or "/__pycache__/" in "/" + n or n.endswith(".pyc")]
    if bad:
        raise BuildError(f"{path.name}: development files in the zip: {bad[:10]}")
    for required in ("__init__.py", MANIFEST_NAME):
        if required not in names:
            raise BuildError(f"{path.name}: lacks {required}")
    wheels = {n.removeprefix("wheels/") for n in names if n.startswith("wheels/")}
    if wheels != expected_wheels:
        raise BuildError(f"{path.name}: wheels {sorted(wheels)} != expected {sorted(expected_wheels)}")
    return names


def build(platforms: list[str], out: Path, blender_ext: Path, build_dir: Path) -> dict:
    t0 = time.monotonic()
    manifest = load_manifest()
    lock = load_lock()
    check_manifest_matches_lock(manifest, lock)
    if not set(platforms) <= set(manifest["platforms"]):
        raise BuildError(f"platforms {platforms} not all in the manifest's {manifest['platforms']}")

    selected = [e for e in lock if set(e["platforms"]) & set(platforms)]
    stage = build_dir / "stage"
    log(f"staging into {stage}")
    staged_dirs = stage_sources(stage)
    log(f"  packages: {', '.join(staged_dirs)}")

    log(f"wheels: {len(selected)} of {len(lock)} for {', '.join(platforms)}")
    t_fetch = time.monotonic()
    downloaded, cached = fetch_wheels(selected, build_dir / "wheels")
    t_fetch = time.monotonic() - t_fetch
    (stage / "wheels").mkdir()
    for e in selected:
        _link_or_copy(build_dir / "wheels" / e["file"], stage / "wheels" / e["file"])
    if sorted(platforms) != sorted(manifest["platforms"]):
        keep = [w for w in manifest["wheels"]
                if w.removeprefix("./wheels/") in {e["file"] for e in selected}]
        restrict_manifest(stage / MANIFEST_NAME, [p for p in manifest["platforms"] if p in platforms], keep)

    tags = tags_file_for(blender_ext)
    tags_arg = [f"--valid-tags={tags}"] if tags else []
    if not tags:
        log("  warning: Blender's tags.py not found next to blender_ext.py, tags not checked")
    out.mkdir(parents=True, exist_ok=True)
    version = manifest["version"]
    zips = {p: out / f"{manifest['id']}-{version}-{p.replace('-', '_')}.zip" for p in platforms}
    for z in zips.values():
        if z.exists():
            z.unlink()

    log(f"building with {blender_ext}")
    t_build = time.monotonic()
    run_tool([sys.executable, str(blender_ext), "build", "--source-dir", str(stage),
              "--output-dir", str(out), "--split-platforms", *tags_arg])
    t_build = time.monotonic() - t_build

    results = []
    for plat, z in zips.items():
        if not z.is_file():
            raise BuildError(f"blender_ext.py did not write {z}")
        run_tool([sys.executable, str(blender_ext), "validate", *tags_arg, str(z)])
        expected = {e["file"] for e in selected if plat in e["platforms"]}
        names = check_zip(z, expected)
        results.append({
            "platform": plat,
            "path": str(z),
            "bytes": z.stat().st_size,
            "files": len(names),
            "wheels": sorted(expected),
            "sha256": sha256_of(z),
        })
    return {
        "id": manifest["id"],
        "version": version,
        "blender_ext": str(blender_ext),
        "tags": str(tags) if tags else None,
        "stage": str(stage),
        "zips": results,
        "wheels_downloaded": downloaded,
        "wheels_cached": cached,
        "seconds": {"fetch": round(t_fetch, 2), "blender_ext_build": round(t_build, 2),
                    "total": round(time.monotonic() - t0, 2)},
    }


def generate_repository(blender_ext: Path, out: Path) -> str:
    """A static extensions repository of the zips in `out`, made by Blender's own tool."""
    run_tool([sys.executable, str(blender_ext), "server-generate", "--repo-dir", str(out), "--html"])
    index = out / "index.json"
    if not index.is_file():
        raise BuildError(f"blender_ext.py server-generate wrote no {index}")
    return index.as_uri()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platforms", nargs="+", choices=ALL_PLATFORMS, default=list(ALL_PLATFORMS),
                    help="platforms to build (default: all four)")
    ap.add_argument("--out", type=Path, default=REPO / "build" / "dist", help="output folder (default build/dist)")
    ap.add_argument("--build-dir", type=Path, default=REPO / "build",
                    help="work folder holding stage/ and the wheel cache wheels/ (default build)")
    ap.add_argument("--blender-ext", help="path to Blender's blender_ext.py (default: found in an installed bpy)")
    ap.add_argument("--repository", action="store_true",
                    help="also write a static extensions repository (index.json, index.html) in --out, "
                         "for Blender's Preferences > Get Extensions > Repositories > Add Remote Repository")
    ap.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    args = ap.parse_args(argv)
    platforms = list(dict.fromkeys(args.platforms))
    try:
        result = build(platforms, args.out.resolve(), find_blender_ext(args.blender_ext), args.build_dir.resolve())
        if args.repository:
            result["repository"] = generate_repository(find_blender_ext(args.blender_ext), args.out.resolve())
    except BuildError as ex:
        log(f"ERROR: {ex}")
        return 1
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for z in result["zips"]:
            print(f"{z['bytes'] / 1e6:8.1f} MB  {z['path']}")
        if result.get("repository"):
            print(f"repository: {result['repository']} (add it in Blender as a remote repository)")
        print(f"built {len(result['zips'])} zip(s) in {result['seconds']['total']:.1f} s "
              f"({result['wheels_downloaded']} wheel(s) downloaded, {result['wheels_cached']} cached)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

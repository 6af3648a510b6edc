"""The extension package: manifest and wheel lock, the built zip, and the zip installed in bpy.

- Manifest/lock consistency needs neither bpy nor the network.
- The linux-x64 zip is built once per module with .ci/build_extension.py (wheels cached in
  build/wheels, so only the first run fetches them from the package registry).
- The installed-extension tests run one fresh bpy session in a subprocess (with the running
  interpreter, which must have bpy) whose BLENDER_USER_RESOURCES is a temporary folder: it
  installs the zip into a user repository, enables it, imports the bundled modules, runs
  `humananim.detect_roles` on Rigify's human metarig, disables, re-enables, disables and
  uninstalls, and writes a JSON report that the tests below check.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import textwrap
import time
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BUILD_SCRIPT = REPO / ".ci" / "build_extension.py"
MANIFEST = REPO / "blender_manifest.toml"
LOCK = REPO / ".ci" / "wheels.lock"
PLATFORMS = ["linux-x64", "windows-x64", "macos-arm64", "macos-x64"]
BUNDLED = ("scipy", "pyserial", "hidapi")
PYTHONS = ("cp311", "cp313")  # Blender 4.2-5.0 and 5.1+
PKG_ID = "humananim"
REPO_MODULE = "humananim_test"


def _load_build_module():
    spec = importlib.util.spec_from_file_location("humananim_build_extension", BUILD_SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _toml(path: Path) -> dict:
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def _wheel_platforms(filename: str) -> set[str]:
    """Blender platform names for a wheel file name (as blender_ext.py maps them)."""
    tag = filename[:-4].split("-")[-1]
    if tag == "any":
        return set(PLATFORMS)
    out = set()
    for t in tag.split("."):
        if "linux" in t and t.endswith("x86_64"):
            out.add("linux-x64")
        elif t == "win_amd64":
            out.add("windows-x64")
        elif t.startswith("macosx") and t.endswith("arm64"):
            out.add("macos-arm64")
        elif t.startswith("macosx") and t.endswith("x86_64"):
            out.add("macos-x64")
        else:
            out.add("?" + t)
    return out


def _project(filename: str) -> str:
    return filename.split("-")[0].lower()


# ----------------------------------------------------------------------------------------
# (a) manifest and lock, no bpy


def test_manifest_required_fields():
    m = _toml(MANIFEST)
    assert m["schema_version"] == "1.0.0"
    assert m["id"] == PKG_ID and m["type"] == "add-on"
    assert re.fullmatch(r"\d+\.\d+\.\d+", m["version"])
    assert m["blender_version_min"] == "4.2.0"
    assert "blender_version_max" not in m
    assert m["license"] == ["SPDX:GPL-3.0-or-later"]
    assert len(m["tagline"]) <= 64 and re.search(r"[A-Za-z0-9\])]$", m["tagline"])
    assert sorted(m["platforms"]) == sorted(PLATFORMS)  # no windows-arm64: hidapi has no wheel
    perms = m["permissions"]
    assert set(perms) == {"files", "network"}
    for reason in perms.values():
        assert 0 < len(reason) <= 64 and not reason.endswith((".", ",", ";", ":", "!", "?"))
    # The package metadata of the development install carries the same version.
    assert _toml(REPO / "pyproject.toml")["project"]["version"] == m["version"]
    # The build section uses the exclude list (not `paths`, both together are refused).
    build = m["build"]
    assert "paths" not in build
    for pattern in ("/tests/", "/benchmarks/", "/.ci/", "__pycache__/"):
        assert pattern in build["paths_exclude_pattern"]


def test_manifest_wheels_equal_lock():
    m = _toml(MANIFEST)
    lock = _toml(LOCK)["wheel"]
    files = [e["file"] for e in lock]
    assert len(files) == len(set(files)), "a wheel is locked twice"
    listed = m["wheels"]
    assert len(listed) == len(set(listed)), "a wheel is listed twice in the manifest"
    assert all(w.startswith("./wheels/") for w in listed)
    assert sorted(w.removeprefix("./wheels/") for w in listed) == sorted(files)
    # The build script agrees (it refuses to build otherwise).
    build = _load_build_module()
    build.check_manifest_matches_lock(m, build.load_lock(LOCK))


def test_lock_entries_are_consistent():
    lock = _toml(LOCK)["wheel"]
    for e in lock:
        f = e["file"]
        assert re.fullmatch(r"[0-9a-f]{64}", e["sha256"]), f
        assert set(e["platforms"]) == _wheel_platforms(f), f
        assert e["project"].lower() == _project(f) and f.split("-")[1] == e["version"], f
        assert _project(f) != "numpy", "numpy ships with Blender: never bundle it"
    # One pinned version per project.
    versions = {}
    for e in lock:
        versions.setdefault(_project(e["file"]), set()).add(e["version"])
    assert set(versions) == set(BUNDLED)
    assert all(len(v) == 1 for v in versions.values()), versions
    # scipy 1.15 runs on Blender's numpy (1.24-1.26) as well as numpy 2.
    assert versions["scipy"] == {"1.15.3"}
    # Every platform gets every bundled project for both Pythons.
    for plat in PLATFORMS:
        for py in PYTHONS:
            have = {_project(e["file"]) for e in lock if plat in e["platforms"]
                    and (e["python"] == py or e["file"].split("-")[-3].startswith("py"))}
            assert have == set(BUNDLED), (plat, py, have)


def test_manifest_validates_with_blender_ext():
    build = _load_build_module()
    try:
        tool = build.find_blender_ext(None)
    except build.BuildError as ex:
        pytest.skip(str(ex))
    tags = build.tags_file_for(tool)
    args = [f"--valid-tags={tags}"] if tags else []
    res = subprocess.run([sys.executable, str(tool), "validate", *args, str(REPO)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_wheel_hash_mismatch_fails_loudly(tmp_path, monkeypatch):
    build = _load_build_module()
    entry = {"file": "pyserial-3.5-py2.py3-none-any.whl", "sha256": "0" * 64, "platforms": PLATFORMS}

    def fake_download(entries, dest):  # stands in for pip: writes a file with other bytes
        (dest / entries[0]["file"]).write_bytes(b"not the locked wheel")

    monkeypatch.setattr(build, "_pip_download_group", fake_download)
    with pytest.raises(build.BuildError, match="SHA256 MISMATCH"):
        build.fetch_wheels([entry], tmp_path)


# ----------------------------------------------------------------------------------------
# (b) the built linux-x64 zip


@pytest.fixture(scope="module")
def linux_zip() -> dict:
    prebuilt = os.environ.get("HUMANANIM_EXTENSION_ZIP")
    if prebuilt:  # test a zip built elsewhere (e.g. by an earlier CI step) instead of building
        path = Path(prebuilt).resolve()
        return {"platform": "linux-x64", "path": str(path), "bytes": path.stat().st_size}
    # one build folder per environment: CI tests Blender 5.0 and 4.2 side by side
    build_dir = REPO / "build" / f"test-{Path(sys.prefix).name}"
    t0 = time.monotonic()
    res = subprocess.run(
        [sys.executable, str(BUILD_SCRIPT), "--platforms", "linux-x64", "--out", str(build_dir / "dist"),
         "--build-dir", str(build_dir), "--repository", "--json"],
        capture_output=True, text=True, timeout=900,
    )
    if res.returncode != 0:
        pytest.fail("build_extension.py failed:\n" + res.stdout[-3000:] + res.stderr[-5000:])
    info = json.loads(res.stdout)
    info["elapsed"] = time.monotonic() - t0
    (z,) = info["zips"]
    assert z["platform"] == "linux-x64"
    z["repository"] = info["repository"]
    return z


def test_build_writes_an_extensions_repository(linux_zip):
    if "repository" not in linux_zip:
        pytest.skip("a prebuilt zip was given")
    index = Path(linux_zip["repository"].removeprefix("file://"))
    listing = json.loads(index.read_text())
    (entry,) = [p for p in listing["data"] if p["id"] == PKG_ID]
    assert entry["platforms"] == ["linux-x64"]
    assert (index.parent / entry["archive_url"]).resolve() == Path(linux_zip["path"]).resolve()
    assert (index.parent / "index.html").is_file()


def test_zip_has_no_development_files(linux_zip):
    with zipfile.ZipFile(linux_zip["path"]) as zf:
        names = zf.namelist()
    for prefix in ("tests/", "benchmarks/", ".ci/", "build/", ".git/"):
        assert not [n for n in names if n.startswith(prefix)], prefix
    assert "pyproject.toml" not in names and "__main__.py" not in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc") or n.endswith(".blend1")]
    for needed in ("__init__.py", "blender_manifest.toml", "solver/__init__.py",
                   "humananim_addon/__init__.py", "operators/__init__.py", "panels/__init__.py"):
        assert needed in names, needed
    # Data files of the add-on (e.g. humananim_addon/data/mocap/*) travel with it.
    data = REPO / "humananim_addon" / "data"
    if data.is_dir():
        for f in data.rglob("*"):
            if f.is_file() and "__pycache__" not in f.parts and not f.name.startswith("."):
                assert f.relative_to(REPO).as_posix() in names, f


def test_zip_bundles_wheels_for_both_pythons(linux_zip):
    with zipfile.ZipFile(linux_zip["path"]) as zf:
        wheels = [n.removeprefix("wheels/") for n in zf.namelist() if n.startswith("wheels/")]
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    for py in PYTHONS:
        for project in ("scipy", "hidapi"):
            assert [w for w in wheels if _project(w) == project and f"-{py}-{py}-" in w], (project, py)
    assert [w for w in wheels if _project(w) == "pyserial" and "-py2.py3-none-any" in w]
    assert all(_wheel_platforms(w) >= {"linux-x64"} for w in wheels), wheels
    assert not [w for w in wheels if _project(w) == "numpy"]
    # Blender's builder marks the split zip as linux-x64 only, with exactly these wheels.
    gen = manifest["build"]["generated"]
    assert gen["platforms"] == ["linux-x64"]
    assert sorted(w.removeprefix("./wheels/") for w in gen["wheels"]) == sorted(wheels)


# ----------------------------------------------------------------------------------------
# (c) the zip installed in a fresh headless bpy session

BPY_SCRIPT = textwrap.dedent(r'''
    import glob, json, os, sys, time, traceback
    res_dir, zip_path, out_path, repo_module, pkg_id = sys.argv[1:6]
    assert os.environ.get("BLENDER_USER_RESOURCES") == res_dir
    report = {"steps": {}, "errors": [], "times": {}}
    t_start = time.monotonic()

    def step(name, fn):
        t = time.monotonic()
        try:
            report["steps"][name] = fn()
        except BaseException as ex:
            report["steps"][name] = None
            report["errors"].append("%s: %s" % (name, traceback.format_exc()))
        report["times"][name] = round(time.monotonic() - t, 3)

    def dump():
        report["times"]["total"] = round(time.monotonic() - t_start, 3)
        with open(out_path, "w") as fh:
            json.dump(report, fh, indent=1)

    import bpy, addon_utils
    report["bpy_version"] = bpy.app.version_string
    repo_dir = os.path.join(res_dir, "user_repo")
    mod_name = "bl_ext.%s.%s" % (repo_module, pkg_id)

    def op_exists():
        try:
            bpy.ops.humananim.detect_roles.get_rna_type()
            return True
        except KeyError:
            return False

    def add_repo():
        repo = bpy.context.preferences.extensions.repos.new(
            name="HumanAnim test", module=repo_module, custom_directory=repo_dir, source="USER")
        return repo.module

    def install():
        r = bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo=repo_module, enable_on_install=True)
        return {
            "result": sorted(r),
            "manifest_installed": os.path.isfile(os.path.join(repo_dir, pkg_id, "blender_manifest.toml")),
            "enabled": mod_name in bpy.context.preferences.addons,
            "module_loaded": mod_name in sys.modules,
        }

    def site_packages():
        base = os.path.join(res_dir, "extensions", ".local", "lib")
        found = sorted(glob.glob(os.path.join(base, "python3*", "site-packages")))
        return {"dirs": found, "listing": sorted(os.listdir(found[0])) if found else []}

    def imports():
        out = {}
        for name in ("hid", "serial", "scipy"):
            m = __import__(name)
            out[name] = {"file": getattr(m, "__file__", None),
                         "version": getattr(m, "__version__", getattr(m, "VERSION", None))}
        return out

    BUNDLED_CHECK = (
        "import sys; sys.path.insert(0, sys.argv[1]); import numpy, scipy, serial, hid; "
        "from scipy.spatial.transform import Rotation; from scipy.optimize import minimize; "
        "assert all(m.__file__.startswith(sys.argv[1]) for m in (scipy, serial, hid)); "
        "Rotation.from_euler('xyz', [0.1, 0.2, 0.3]).as_quat(); "
        "x = minimize(lambda v: ((v - 1.0) ** 2).sum(), numpy.zeros(3)).x; "
        "assert abs(x - 1).max() < 1e-4; print(scipy.__version__, numpy.__version__)")

    def bundled_check():
        import subprocess
        site = report["steps"]["site_packages"]["dirs"][0]
        r = subprocess.run([sys.executable, "-s", "-c", BUNDLED_CHECK, site],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        return {"returncode": r.returncode, "output": r.stdout}

    def detect_roles():
        out = {"exists": op_exists()}
        addon_utils.enable("rigify", default_set=True)
        bpy.ops.object.armature_human_metarig_add()
        obj = bpy.context.active_object
        out["object"] = [obj.name, obj.type, len(obj.data.bones)]
        if out["exists"]:
            out["result"] = sorted(bpy.ops.humananim.detect_roles())
        return out

    def disable():
        addon_utils.disable(mod_name, default_set=True)
        return {"enabled": mod_name in bpy.context.preferences.addons, "op_exists": op_exists()}

    def enable():
        mod = addon_utils.enable(mod_name, default_set=True)
        return {"module": mod is not None, "enabled": mod_name in bpy.context.preferences.addons,
                "op_exists": op_exists()}

    def uninstall():
        repos = bpy.context.preferences.extensions.repos
        index = [i for i, r in enumerate(repos) if r.module == repo_module][0]
        r = bpy.ops.extensions.package_uninstall(repo_index=index, pkg_id=pkg_id)
        return {"result": sorted(r), "dir_exists": os.path.exists(os.path.join(repo_dir, pkg_id)),
                "enabled": mod_name in bpy.context.preferences.addons}

    step("add_repo", add_repo)
    step("install", install)
    step("site_packages", site_packages)
    step("imports", imports)
    step("bundled_check", bundled_check)
    step("detect_roles", detect_roles)
    step("disable_1", disable)
    step("enable_2", enable)
    step("disable_2", disable)
    step("uninstall", uninstall)
    report["sys_path"] = sys.path
    dump()
    sys.stdout.flush()
    os._exit(0)
''')


@pytest.fixture(scope="module")
def installed(linux_zip, tmp_path_factory) -> dict:
    if importlib.util.find_spec("bpy") is None:
        # Not imported here: the bpy session must start fresh in its own process, after
        # BLENDER_USER_RESOURCES is set.
        pytest.skip("the bpy module is not installed in this interpreter")
    tmp = tmp_path_factory.mktemp("bpy_user")
    res_dir = tmp / "resources"
    res_dir.mkdir()
    script = tmp / "install_extension.py"
    script.write_text(BPY_SCRIPT)
    out = tmp / "report.json"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(res_dir), PYTHONNOUSERSITE="1")
    t0 = time.monotonic()
    res = subprocess.run(
        [sys.executable, str(script), str(res_dir), str(Path(linux_zip["path"]).resolve()), str(out),
         REPO_MODULE, PKG_ID],
        capture_output=True, text=True, env=env, timeout=300,
    )
    elapsed = time.monotonic() - t0
    log = (res.stdout[-4000:] + "\n--- stderr ---\n" + res.stderr[-4000:])
    if not out.is_file():
        pytest.fail(f"the bpy session wrote no report (exit {res.returncode}):\n{log}")
    report = json.loads(out.read_text())
    report["elapsed"] = elapsed
    report["log"] = log
    report["res_dir"] = str(res_dir)
    return report


def _step(report: dict, name: str):
    value = report["steps"].get(name)
    errors = [e for e in report["errors"] if e.startswith(name + ":")]
    assert value is not None, f"step {name} failed:\n" + "\n".join(errors) + "\n" + report["log"]
    return value


def test_installed_extension_enables(installed):
    inst = _step(installed, "install")
    assert inst["result"] == ["FINISHED"]
    # package_install_files says FINISHED even when it installed nothing: check for real.
    assert inst["manifest_installed"], installed["log"]
    assert inst["enabled"] and inst["module_loaded"], installed["log"]


def test_installed_extension_uses_bundled_wheels(installed):
    site = _step(installed, "site_packages")
    assert len(site["dirs"]) == 1, site
    site_dir = os.path.realpath(site["dirs"][0])
    assert site_dir.endswith(os.path.join("python%d.%d" % sys.version_info[:2], "site-packages"))
    listing = set(site["listing"])
    assert {"scipy", "serial"} <= listing and any(n.startswith("hid.") for n in listing), listing
    assert any(n.startswith("scipy-1.15.3") for n in listing), listing
    mods = _step(installed, "imports")
    # hidapi is in no venv: `import hid` must find the extension's extracted wheel.
    assert os.path.realpath(mods["hid"]["file"]).startswith(site_dir + os.sep), mods["hid"]
    # scipy and pyserial may be shadowed by a venv that has them (sys.path order decides):
    # whichever copy won must import; the bundled scipy is checked on its own below.
    for name in ("serial", "scipy"):
        assert mods[name]["file"], mods


def test_bundled_scipy_runs_with_this_numpy(installed):
    """The bundled scipy 1.15.3 (not a venv's copy) imports and runs with the numpy present.

    Checked inside the bpy session while the extension is installed (uninstalling removes the
    extracted wheels), in a plain Python subprocess whose sys.path starts with the wheel folder.
    """
    chk = _step(installed, "bundled_check")
    assert chk["returncode"] == 0, chk["output"]
    scipy_version, numpy_version = chk["output"].split()[:2]
    assert scipy_version == "1.15.3", chk


def test_detect_roles_operator_runs_on_rigify_metarig(installed):
    dr = _step(installed, "detect_roles")
    assert dr["object"][1] == "ARMATURE" and dr["object"][2] > 100, dr
    # get_rna_type() found the operator (hasattr on bpy.ops is always true).
    assert dr["exists"], "bpy.ops.humananim.detect_roles is not registered by the add-on"
    assert dr["result"] == ["FINISHED"], dr


def test_disable_enable_cycle_and_uninstall(installed):
    d1 = _step(installed, "disable_1")
    assert not d1["enabled"] and not d1["op_exists"], d1
    e2 = _step(installed, "enable_2")
    assert e2["module"] and e2["enabled"], installed["log"]
    assert e2["op_exists"] == _step(installed, "detect_roles")["exists"]
    d2 = _step(installed, "disable_2")
    assert not d2["enabled"] and not d2["op_exists"], d2
    un = _step(installed, "uninstall")
    assert un["result"] == ["FINISHED"] and not un["dir_exists"], un

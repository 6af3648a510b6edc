"""The code's layout as docs/design.md describes it ("The bridge: one home per capability"): each
capability's folder in humananim_addon/ holds its settings, its job and its command where the table
says; the bridge never imports an operator or a panel (data flows one way); solver/ imports no bpy
and nothing of the Blender side; every command's options come from the one argument-parsing layer.
Read from the source files (no Blender needed)."""

import ast
import os
import re

import pytest

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", ".."))
BRIDGE = os.path.join(ROOT, "humananim_addon")
DESIGN = os.path.join(ROOT, "docs", "design.md")
BLENDER_MODULES = {"bpy", "bpy_extras", "mathutils", "gpu", "gpu_extras", "bmesh", "blf", "aud", "idprop"}
UI_PACKAGES = {"operators", "panels"}


def layout_table():
    """{folder: {"settings": [files], "job": [files], "command": [files]}} from the design page's
    table: the `.py` names in each cell (a cell without one, "none", holds no file)."""
    text = open(DESIGN, encoding="utf-8").read()
    section = text.split("## The bridge: one home per capability", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ") and "`" in line.split("|")[2]]
    table = {}
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        folder = re.search(r"`([\w/]+)/`", cells[1]).group(1)
        table[folder] = {part: re.findall(r"`(\w+\.py)`", cell)
                         for part, cell in zip(("settings", "job", "command"), cells[2:5])}
    return table


def python_files(top):
    for folder, _, files in os.walk(top):
        for name in files:
            if name.endswith(".py"):
                yield os.path.join(folder, name)


def imported_modules(path, package):
    """The absolute dotted names a module imports (relative imports resolved against `package`,
    the module's package under the repository root, e.g. "humananim_addon.cloth")."""
    tree = ast.parse(open(path, encoding="utf-8").read())
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".") if package else []
                keep = len(parts) - node.level + 1  # `..` from humananim_addon.cloth: humananim_addon
                base = parts[:keep] if keep > 0 else []  # at the repository's root package
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module
            names.append(prefix)
            names += [f"{prefix}.{a.name}" if prefix else a.name for a in node.names]
    return names


def package_of(path):
    rel = os.path.relpath(os.path.dirname(path), ROOT)
    return "" if rel == "." else rel.replace(os.sep, ".")


def test_design_page_lists_every_capability_folder():
    table = layout_table()
    assert {"simulation", "motion_control", "hands", "walking", "flexible", "cloth", "capture", "synthesis",
            "sequence", "cleanup", "batch", "qa"} <= set(table)
    folders = {name for name in os.listdir(BRIDGE) if os.path.isfile(os.path.join(BRIDGE, name, "__init__.py"))}
    assert set(table) - {"rig"} <= folders
    # every folder of the bridge is a capability in the table, or the device protocols (bpy-free)
    assert folders - set(table) <= {"devices"}


@pytest.mark.parametrize("folder", sorted(layout_table()))
def test_capability_folder_holds_what_the_design_page_says(folder):
    parts = layout_table()[folder]
    for part, files in parts.items():
        for name in files:
            if folder == "rig" and part != "job":
                continue  # the rig's settings and command are the shared properties.py and cli.py at the top
            assert os.path.isfile(os.path.join(BRIDGE, folder, name)), f"humananim_addon/{folder}/{name}"
    for name in parts["settings"]:
        if folder == "rig":
            continue
        tree = ast.parse(open(os.path.join(BRIDGE, folder, name), encoding="utf-8").read())
        groups = [n.name for n in tree.body if isinstance(n, ast.ClassDef)
                  and any("PropertyGroup" in ast.unparse(b) for b in n.bases)]
        assert groups, f"{folder}/{name} defines no property group"


def test_every_command_module_is_dispatched_and_builds_its_options_from_the_one_layer():
    cli_source = open(os.path.join(BRIDGE, "cli.py"), encoding="utf-8").read()
    dispatched = set(re.search(r"COMMAND_MODULES = \(([^)]*)\)", cli_source).group(1).replace('"', "")
                     .replace("\n", " ").replace(" ", "").split(","))
    for folder, parts in layout_table().items():
        for name in parts["command"]:
            if folder == "rig":
                continue
            module = f"{folder}.{name[:-3]}"
            path = os.path.join(BRIDGE, folder, name)
            assert module in dispatched or folder in dispatched, f"{module} is not in cli.COMMAND_MODULES"
            tree = ast.parse(open(path, encoding="utf-8").read())
            assert any(isinstance(n, ast.FunctionDef) and n.name == "add_commands" for n in tree.body), module
    for path in python_files(BRIDGE):
        if os.path.basename(path) == "arguments.py":
            continue
        imports = imported_modules(path, package_of(path))
        assert "argparse" not in imports, f"{os.path.relpath(path, ROOT)} builds its own argparse pieces"


def test_the_bridge_never_imports_an_operator_or_a_panel():
    """Data flows one way: operators and panels call the bridge, never the other way. The add-on's
    registration (humananim_addon/__init__.py) is the one place that loads them, after the bridge."""
    offenders = []
    for path in python_files(BRIDGE):
        if os.path.relpath(path, BRIDGE) == "__init__.py":
            continue
        for name in imported_modules(path, package_of(path)):
            if name.split(".")[0] in UI_PACKAGES:
                offenders.append(f"{os.path.relpath(path, ROOT)} imports {name}")
    assert not offenders, offenders


def test_the_solver_imports_no_blender_and_nothing_of_the_blender_side():
    offenders = []
    for path in python_files(os.path.join(ROOT, "solver")):
        for name in imported_modules(path, package_of(path)):
            top = name.split(".")[0]
            if top in BLENDER_MODULES or top in UI_PACKAGES | {"humananim_addon"}:
                offenders.append(f"{os.path.relpath(path, ROOT)} imports {name}")
    assert not offenders, offenders


def test_device_protocols_import_no_blender():
    for path in python_files(os.path.join(BRIDGE, "devices")):
        for name in imported_modules(path, package_of(path)):
            assert name.split(".")[0] not in BLENDER_MODULES, f"{os.path.relpath(path, ROOT)} imports {name}"


@pytest.mark.parametrize("top", ["humananim_addon", "operators", "panels", "solver"])
def test_every_relative_import_names_a_module_that_exists(top):
    """A module moved into a folder must reach the others one level further up: a relative import
    inside a function is only run when that code runs, so check every one here."""
    missing = []
    for path in python_files(os.path.join(ROOT, top)):
        tree = ast.parse(open(path, encoding="utf-8").read(), path)
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom) or not node.level:
                continue
            base = os.path.dirname(path)
            for _ in range(node.level - 1):
                base = os.path.dirname(base)
            if os.path.normpath(base) == ROOT:  # `from .. import register`: the add-on's package
                continue
            target = os.path.join(base, *(node.module or "").split("."))
            if not (os.path.isdir(target) or os.path.isfile(target + ".py")):
                missing.append(f"{os.path.relpath(path, ROOT)}:{node.lineno} from {'.' * node.level}{node.module or ''}")
    assert not missing, missing


def test_nothing_takes_an_attribute_of_a_capability_folder_that_holds_only_modules():
    """`from humananim.humananim_addon import walking` gives the folder, whose __init__ defines
    nothing: code written before the move (`walking.run`) fails only when it runs. Tests,
    benchmarks and the docs scripts import the module they use (`walking.job`)."""
    bare = {name for name in os.listdir(BRIDGE) if os.path.isfile(os.path.join(BRIDGE, name, "__init__.py"))
            and not any(isinstance(n, (ast.FunctionDef, ast.ClassDef, ast.Assign, ast.ImportFrom))
                        for n in ast.parse(open(os.path.join(BRIDGE, name, "__init__.py")).read()).body)}
    wrong = []
    for top in ("tests", "benchmarks", "docs"):
        for path in python_files(os.path.join(ROOT, top)):
            for node in ast.walk(ast.parse(open(path, encoding="utf-8").read(), path)):
                if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("humananim_addon"):
                    wrong += [f"{os.path.relpath(path, ROOT)}:{node.lineno} {a.name}" for a in node.names
                              if a.name in bare]
    assert not wrong, wrong

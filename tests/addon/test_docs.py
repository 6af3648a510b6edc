"""The manual: every panel has its page in docs/panels/ with a picture of its result, every
picture the README and the pages show exists and is small, and the README stays a manual (at
most 250 lines, no measurement history). Panels are found in the code, so a new panel needs a
page before this passes."""

import ast
import os
import re

import pytest

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", ".."))
PAGES = os.path.join(ROOT, "docs", "panels")
README = os.path.join(ROOT, "README.md")
PICTURE_MARKERS = ("<!-- no picture", "<!-- picture pending")  # a page says why it has no picture yet
HISTORY = ("this stop", "since then", "callgrind", "instructions per", "the code before", "on this machine",
           "this round")


def panel_classes():
    """{page name: [(class name, bl_label)]} of every bpy Panel class in panels/*.py (the page of
    panels/rig.py is docs/panels/rig.md), and the add-on's preferences."""
    found = {}
    sources = [os.path.join(ROOT, "panels", f) for f in sorted(os.listdir(os.path.join(ROOT, "panels")))
               if f.endswith(".py")]
    for path in sources + [os.path.join(ROOT, "humananim_addon", "preferences.py")]:
        tree = ast.parse(open(path, encoding="utf-8").read())
        for node in tree.body:
            if not isinstance(node, ast.ClassDef):
                continue
            bases = {ast.unparse(b) for b in node.bases}
            if not bases & {"bpy.types.Panel", "Panel", "bpy.types.AddonPreferences", "AddonPreferences"}:
                continue
            label = next((ast.literal_eval(s.value) for s in node.body if isinstance(s, ast.Assign)
                          and any(getattr(t, "id", None) == "bl_label" for t in s.targets)), None)
            page = "preferences" if "preferences" in os.path.basename(path) else os.path.basename(path)[:-3]
            found.setdefault(page, []).append((node.name, label))
    return found


def page_text(name):
    path = os.path.join(PAGES, f"{name}.md")
    assert os.path.exists(path), f"no page docs/panels/{name}.md for {[c for c, _ in panel_classes()[name]]}"
    return open(path, encoding="utf-8").read()


def pictures_in(path):
    """The local pictures a markdown file shows (markdown images and <img> tags), as paths."""
    text = open(path, encoding="utf-8").read()
    refs = re.findall(r"!\[[^\]]*\]\(([^)\s]+)", text) + re.findall(r"<img[^>]*\ssrc=\"([^\"]+)\"", text)
    return [os.path.normpath(os.path.join(os.path.dirname(path), r)) for r in refs if "://" not in r]


def test_panels_are_found_in_the_code():
    found = panel_classes()
    assert {"rig", "simulate", "motion_control", "cloth", "hands", "preferences"} <= set(found)
    assert ("VIEW3D_PT_humananim_mass", "Mass Model") in found["rig"]


@pytest.mark.parametrize("page", sorted(panel_classes()))
def test_every_panel_has_a_page_naming_it_with_a_picture(page):
    text = page_text(page)
    for cls, label in panel_classes()[page]:
        assert label is None or label in text, f"docs/panels/{page}.md does not name the '{label}' panel ({cls})"
    pictures = pictures_in(os.path.join(PAGES, f"{page}.md"))
    assert pictures or any(m in text for m in PICTURE_MARKERS), \
        f"docs/panels/{page}.md shows no picture of its result (or says why)"


def test_every_registered_panel_has_a_page():
    bpy = pytest.importorskip("bpy")
    from humananim import panels
    found = {cls for classes in panel_classes().values() for cls, _ in classes}
    registered = {c.__name__ for c in panels.CLASSES if issubclass(c, bpy.types.Panel)}
    assert registered and registered <= found, f"registered panels not found in panels/*.py: {registered - found}"


def test_pictures_exist_and_are_small():
    files = [README] + [os.path.join(PAGES, f) for f in sorted(os.listdir(PAGES)) if f.endswith(".md")]
    shown = {p for f in files for p in pictures_in(f)}
    assert len(shown) >= 4
    for picture in sorted(shown):
        assert os.path.exists(picture), f"missing picture {os.path.relpath(picture, ROOT)}"
        assert os.path.getsize(picture) < 150_000, f"{os.path.relpath(picture, ROOT)} is over 150 KB"
    readme = set(pictures_in(README))
    for name in ("control", "skirt", "grasp", "walk", "qa"):  # the results the issue asks the README to show
        assert os.path.join(ROOT, "docs", "pictures", f"{name}.png") in readme


def test_readme_is_a_manual():
    text = open(README, encoding="utf-8").read()
    assert len(text.splitlines()) <= 250
    for phrase in HISTORY:
        assert phrase not in text.lower(), f"measurement history in the README: '{phrase}'"
    for topic in ("docs/devices.md", "docs/cloth.md", "docs/batch.md", "docs/qa.md", "docs/design.md",
                  "docs/departures.md", "bash .ci/demo", "bash .ci/run", "python -m humananim batch",
                  "python benchmarks/results.py"):
        assert topic in text, f"the README does not mention {topic}"
    for doc in ("docs/design.md", "docs/departures.md"):
        assert os.path.exists(os.path.join(ROOT, doc))

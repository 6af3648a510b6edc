"""Development install: the repository root is the package `humananim` (as Blender loads it)."""

from setuptools import find_packages, setup

ROOTS = ("solver", "humananim_addon", "operators", "panels")
packages = ["humananim"] + [f"humananim.{p}" for p in find_packages(".", include=[f"{r}*" for r in ROOTS])]

setup(packages=packages, package_dir={"humananim": "."})

"""pytest imports test modules by their base name (no packages under tests/): two files with one
name in different folders stop the whole run at collection."""

from collections import Counter
from pathlib import Path


def test_test_modules_have_unique_names():
    tests = Path(__file__).resolve().parent.parent
    names = Counter(p.name for p in tests.rglob("test_*.py"))
    assert not [n for n, c in names.items() if c > 1]

"""The benchmarks' JSON contract and benchmarks/RESULTS.md (issue 24): every benchmark script takes
--json, the committed results follow the contract, and RESULTS.md is what results.py renders from
them. Nothing here runs a benchmark or looks at a time."""

import ast
import importlib.util
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def load_module(name):
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


results = load_module("results")
machine = load_module("machine")
SCRIPTS = results.benchmark_names()
# benchmarks/cloth.py is given its results/cloth.json on the cloth branch (issue 29) at the same time:
# drop this mark once both are merged
PENDING = {}  # {script: pytest.mark.xfail(reason=...)} for a benchmark that has not yet written its result


def option_strings(source):
    """Every literal option string given to an add_argument call in `source`."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_argument":
            found |= {a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)}
    return found


def test_the_benchmark_list_is_the_scripts_without_the_helpers():
    assert "machine" not in SCRIPTS and "results" not in SCRIPTS
    for name in ("actions", "dynamics", "grasp", "transitions", "walking", "control", "compression"):
        assert name in SCRIPTS


@pytest.mark.parametrize("name", [pytest.param(n, marks=PENDING.get(n, ())) for n in SCRIPTS])
def test_every_benchmark_takes_json_and_writes_its_result(name):
    source = (BENCHMARKS / f"{name}.py").read_text()
    assert "--json" in option_strings(source), f"benchmarks/{name}.py has no --json option"
    # its --json writes benchmarks/results/<name>.json: through machine.emit, or by its own name
    assert "emit(" in source or f"{name}.json" in source, f"benchmarks/{name}.py writes no results/{name}.json"
    docstring = ast.get_docstring(ast.parse(source)) or ""
    assert docstring, f"benchmarks/{name}.py says nowhere what it measures"
    for history in ("since then", "this stop", "Measured here"):
        assert history not in docstring, f"benchmarks/{name}.py's docstring holds measurement history"


def test_machine_builds_objects_that_follow_the_contract(tmp_path):
    obj = machine.result("example", [machine.claim("a ratio", 2.5, "x", "> 2", True),
                                     machine.claim("a figure", 3, "ms")], extra=1)
    assert results.check(obj, "example") is None
    assert obj["claims"][1]["aim"] is None and obj["claims"][1]["met"] is None
    path = machine.emit(obj, directory=str(tmp_path))
    good, bad = results.load(str(tmp_path))
    assert path.endswith("example.json") and list(good) == ["example"] and not bad
    assert results.check({**obj, "claims": [{"claim": "no value"}]}, "example") is not None
    assert results.check(obj, "other") is not None


def test_committed_results_follow_the_contract_and_render():
    good, bad = results.load()
    assert not bad, f"results not following the contract: {bad}"
    assert set(good) <= set(SCRIPTS), "a result without its benchmark script"
    assert {"actions", "dynamics", "grasp", "transitions", "walking"} <= set(good)
    for name, obj in good.items():
        assert obj["claims"], f"results/{name}.json has no claims"
        for c in obj["claims"]:
            assert c["met"] is None or c["aim"], f"{name}: a claim met without an aim"
    text = results.render(good, bad, SCRIPTS)
    for name, obj in good.items():
        assert f"## {name}" in text
        assert all(results.cell(c["claim"]) in text for c in obj["claims"])


def test_committed_results_md_is_what_results_py_renders():
    good, bad = results.load()
    assert (BENCHMARKS / "RESULTS.md").read_text() == results.render(good, bad, SCRIPTS), \
        "benchmarks/RESULTS.md is stale: run `python benchmarks/results.py`"

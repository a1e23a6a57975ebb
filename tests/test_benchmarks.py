"""The benchmark scripts stay runnable: every name they import from nerif (and from each other) exists, so a name
moved in the package cannot leave a benchmark that fails on its first line (``benchmarks/flows.py`` did)."""
import ast
import importlib
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(BENCHMARKS.glob("*.py"))


def imported_names(script: Path) -> list[tuple[str, str]]:
    """(module, name) of every ``from M import name`` at any depth of ``script``, for M in nerif or the benchmarks."""
    siblings = {p.stem for p in SCRIPTS}
    out = []
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            top = node.module.split(".")[0]
            if top == "nerif" or top in siblings:
                out += [(node.module, a.name) for a in node.names if a.name != "*"]
    return out


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_every_name_a_benchmark_imports_exists(script, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    missing = [f"{m}.{n}" for m, n in imported_names(script) if not hasattr(importlib.import_module(m), n)
               and importlib.util.find_spec(f"{m}.{n}") is None]
    assert not missing, f"{script.name} imports names that do not exist: {missing}"


def test_the_check_sees_a_moved_name(tmp_path, monkeypatch):
    bad = tmp_path / "moved.py"
    bad.write_text("from nerif.data.scene import outside_the_box\n")
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    (m, n), = imported_names(bad)
    assert not hasattr(importlib.import_module(m), n)

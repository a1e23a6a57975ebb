"""The package's layout as the README states it: imports run one way, down the README's chain of layers, and
never in a circle. Read from the sources (every ``from nerif...`` and ``import nerif...``, at the top of a module
or inside a function), not by importing them."""
import ast
import re
from pathlib import Path

import nerif

TOP = Path(nerif.__file__).resolve().parent
README = TOP.parent / "README.md"


def readme_layers() -> list[set[str]]:
    """The README's chain ``Imports run one way: a/b -> c -> ...``: top-level modules and packages of nerif, from
    the entry down, one set per layer."""
    line = next(ln for ln in README.read_text().splitlines() if ln.startswith("Imports run one way:"))
    chain = line.split(":", 1)[1].strip().strip("`. ")
    return [set(re.findall(r"[A-Za-z_]+", part)) for part in chain.split("->")]


def unit(module: str) -> str:
    """``nerif.data.scene`` -> ``data``; ``nerif.app`` -> ``app``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "nerif"


def module_name(path: Path) -> str:
    parts = path.relative_to(TOP.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports() -> dict[str, set[str]]:
    """Module -> the nerif modules it imports (``from nerif.a import b`` counts as ``nerif.a``, and as
    ``nerif.a.b`` where b is a module)."""
    modules = {module_name(p): p for p in TOP.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        out = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("nerif"):
                out.add(node.module)
                out.update(f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in modules)
            elif isinstance(node, ast.Import):
                out.update(a.name for a in node.names if a.name.startswith("nerif"))
        graph[name] = out - {name}
    return graph


def test_every_import_runs_down_the_readmes_chain():
    layers = readme_layers()
    level = {u: k for k, layer in enumerate(layers) for u in layer}
    units = {unit(m) for m in imports()} - {"nerif"}
    assert units <= set(level), f"modules or packages the README's chain does not name: {units - set(level)}"
    upward = [f"{a} imports {b}" for a, bs in imports().items() for b in bs
              if unit(a) != "nerif" and unit(b) != unit(a) and level[unit(b)] < level[unit(a)]]
    assert not upward, "imports against the README's chain: " + "; ".join(sorted(upward))


def test_no_module_imports_itself_through_others():
    graph = imports()
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(m, path):
        state[m] = 1
        for n in graph.get(m, ()):
            if state.get(n) == 1:
                raise AssertionError("an import circle: " + " -> ".join(path[path.index(n):] + [n]))
            if n in graph and n not in state:
                visit(n, path + [n])
        state[m] = 2

    for m in graph:
        if m not in state:
            visit(m, [m])

"""The packages' import graph: no cycles among the project's modules, counting every import of
one anywhere in a file (module level, ``if TYPE_CHECKING:`` blocks, inside functions, relative
imports), and the layering the architecture promises (generator imports neither perception nor
sms3d_env; perception does not import sms3d_env; only sms3d_env, the top package, may import the
others)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("generator", "perception", "sms3d_env")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(tree: ast.AST, name: str, is_package: bool) -> set[str]:
    """Every name module ``name`` imports anywhere in ``tree`` (``ast.walk``: module level,
    ``TYPE_CHECKING`` blocks, functions, classes), relative imports resolved; ``from m import x``
    gives ``m`` and ``m.x`` (``x`` may be a submodule)."""
    package = name.split(".") if is_package else name.split(".")[:-1]
    targets: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets |= {module} | {f"{module}.{a.name}" for a in node.names}
    return targets


def _graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports, anywhere in its file (a lazy import still runs
    the other module, and a ``TYPE_CHECKING`` one still ties the two together)."""
    paths = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        deps = _imports(tree, name, path.name == "__init__.py")
        graph[name] = {d for d in deps if d in paths and d != name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for dep in sorted(graph[node]):
            if dep not in index:
                visit(dep)
                low[node] = min(low[node], low[dep])
            elif dep in on_stack:
                low[node] = min(low[node], index[dep])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


def test_every_kind_of_import_counts():
    source = (
        "from __future__ import annotations\n"
        "from typing import TYPE_CHECKING\n"
        "import pkg.a\n"
        "if TYPE_CHECKING:\n"
        "    from pkg.b import Thing\n"
        "def f():\n"
        "    from pkg import c\n"
        "    class K:\n"
        "        import pkg.d as d\n"
        "from . import e\n"
        "from .f import g\n"
        "from ..top import h\n"
    )
    found = _imports(ast.parse(source), "root.pkg.mod", is_package=False)
    assert {"pkg.a", "pkg.b", "pkg.c", "pkg.d", "root.pkg.e", "root.pkg.f", "root.pkg.f.g",
            "root.top", "root.top.h"} <= found
    assert "root.pkg.x" in _imports(ast.parse("from .x import y"), "root.pkg", is_package=True)


def test_the_cycle_finder_reports_each_cycle():
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}
    assert _cycles(graph) == [["a", "b"], ["c", "d", "e"]]


def test_imports_have_no_cycle():
    graph = _graph()
    cycles = _cycles(graph)
    assert not cycles, "import cycles (a module -> those of its cycle it imports):\n" + "\n\n".join(
        "\n".join(f"  {m} -> {', '.join(sorted(graph[m] & set(c)))}" for m in c) for c in cycles)


def test_lower_packages_never_import_higher_ones():
    above = {"generator": ("perception", "sms3d_env"), "perception": ("sms3d_env",)}
    for module, deps in _graph().items():  # lazy and TYPE_CHECKING imports count here too
        for higher in above.get(module.split(".")[0], ()):
            assert not any(d.split(".")[0] == higher for d in deps), (module, sorted(deps))


def _reached(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or through others."""
    seen, stack = set(), [start]
    while stack:
        for dep in graph[stack.pop()] - seen:
            seen.add(dep)
            stack.append(dep)
    return seen


def test_the_pickers_and_the_saved_policies_need_nothing_of_training():
    """The pickers (the policy picker among them) and the saved-policy files they load read apart
    from training: none of their modules reaches ``sms3d_env.training`` through any chain of
    imports, lazy ones included; training uses them, never the other way."""
    graph = _graph()
    for module in sorted(graph):
        if module.split(".")[:2] in (["sms3d_env", "pickers"], ["sms3d_env", "policies"]):
            reached = sorted(m for m in _reached(graph, module) if m.startswith("sms3d_env.training"))
            assert not reached, (module, reached)

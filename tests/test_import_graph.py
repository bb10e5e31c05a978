"""The packages' import graph: no cycles among module-level imports, and the layering the
architecture promises (generator imports neither perception nor sms3d_env; perception does not
import sms3d_env; only sms3d_env, the top package, may import the others)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("generator", "perception", "sms3d_env")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _graph(module_level: bool = True) -> dict[str, set[str]]:
    """Module -> the project modules it imports: at module level (imports inside functions are
    deliberate lazy loads, which cannot form a cycle at import time), or anywhere."""
    modules = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps = set()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in tree.body if module_level else ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            deps |= {t for t in targets if t in modules and t != name}
        graph[name] = deps
    return graph


def test_module_level_imports_have_no_cycle():
    graph, state, stack = _graph(), {}, []

    def visit(node: str) -> None:
        state[node] = "open"
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == "open":
                cycle = stack[stack.index(dep):] + [dep]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if dep not in state:
                visit(dep)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node)


def test_lower_packages_never_import_higher_ones():
    above = {"generator": ("perception", "sms3d_env"), "perception": ("sms3d_env",)}
    for module, deps in _graph(module_level=False).items():  # lazy imports count here
        for higher in above.get(module.split(".")[0], ()):
            assert not any(d.split(".")[0] == higher for d in deps), (module, sorted(deps))

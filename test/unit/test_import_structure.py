"""The package's import structure: no cycle, ROS only in ``nodes/``, lower layers never import upper ones.

Every module of ``battery_predictor`` is read with :mod:`ast` (nothing is imported): each ``import``
and ``from ... import`` counts, at module level and inside functions alike, so an import moved into
a function to dodge a cycle is still an edge. Imports under ``if TYPE_CHECKING:`` never run and are
left out of the cycle check; the layer rule counts them too (a lower layer should not even name an
upper one's types). ``from package import name`` is an edge to ``package.name`` when that is a
module, else to ``package``; importing a submodule is not counted as an edge to its parent
``__init__`` (Python has that one in ``sys.modules`` before any child runs).

The layers, lowest first (docs/architecture.md). A module may import its own layer and the layers
below it, never one above:

0. foundation: ``errors``, ``conventions``, ``jsonutil``, ``recording``, ``ocp``, ``params_checks``,
   ``params``, ``config``, ``io``, ``plots``, ``processes`` (data types, files, params, helpers);
1. models: ``simulation`` (the pack model and its extensions), ``profiles`` (loads, routes, station);
2. cores: ``fitting``, ``prediction``, ``monitor``;
3. applications: ``diagnosis``, ``lab``, ``replay``;
4. ``evaluation`` and ``nodes`` (the only ROS package);
5. ``cli``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "battery_predictor"

LAYERS: tuple[frozenset[str], ...] = (
    frozenset({"__init__", "errors", "conventions", "jsonutil", "recording", "ocp", "params_checks", "params",
               "config", "io", "plots", "processes"}),
    frozenset({"simulation", "profiles"}),
    frozenset({"fitting", "prediction", "monitor"}),
    frozenset({"diagnosis", "lab", "replay"}),
    frozenset({"evaluation", "nodes"}),
    frozenset({"cli"}),
)
#: Top-level modules of ROS 2 (rclpy and message packages): only ``nodes/`` may import them.
ROS_MODULES = ("rclpy", "rosidl_runtime_py", "rosbag2_py", "battery_predictor_msgs", "builtin_interfaces",
               "sensor_msgs", "std_msgs", "std_srvs", "diagnostic_msgs")
ROS_PACKAGE = "nodes"


def module_names(root: Path) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``) for every ``.py`` below ``root``."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return out


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and ast.unparse(node.test).split(".")[-1] == "TYPE_CHECKING":
            skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return skip


def imports(root: Path) -> list[tuple[str, str, int, bool]]:
    """Every import in the package below ``root``: (importer, imported module, line, under TYPE_CHECKING).

    The imported module is a module of the package where it resolves to one, else the absolute
    name as written (a third-party module).
    """
    mods = module_names(root)
    out = []
    for name, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        skip = _type_checking_nodes(tree)
        base = name if is_pkg else name.rpartition(".")[0]
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    src = base
                    for _ in range(node.level - 1):
                        src = src.rpartition(".")[0]
                    src = f"{src}.{node.module}" if node.module else src
                else:
                    src = node.module or ""
                targets = [f"{src}.{a.name}" if f"{src}.{a.name}" in mods else src for a in node.names]
            for target in targets:
                resolved = target
                while resolved not in mods and "." in resolved and resolved.split(".")[0] == root.name:
                    resolved = resolved.rpartition(".")[0]
                out.append((name, resolved if resolved in mods else target, node.lineno, id(node) in skip))
    return out


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the directed graph ``edges`` (as a closed list of nodes), or None."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        stack.pop()
        state[node] = 2
        return None

    for start in sorted(edges):
        if start not in state and (found := visit(start)) is not None:
            return found
    return None


def module_graph(root: Path) -> dict[str, set[str]]:
    """Edges between the package's own modules (imports under ``TYPE_CHECKING`` left out)."""
    mods = module_names(root)
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for importer, imported, _, type_only in imports(root):
        if imported in mods and imported != importer and not type_only:
            edges[importer].add(imported)
    return edges


def layer_of(module: str) -> int:
    top = module.split(".")[1] if "." in module else "__init__"
    for k, layer in enumerate(LAYERS):
        if top in layer:
            return k
    raise AssertionError(f"{module}: top-level name {top!r} is in no layer; add it to LAYERS (and the docstring)")


def test_the_package_has_no_import_cycle():
    cycle = find_cycle(module_graph(PACKAGE))
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_every_top_level_module_has_a_layer():
    tops = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
            if (p.suffix == ".py" or (p / "__init__.py").is_file())}
    assert tops <= set().union(*LAYERS), sorted(tops - set().union(*LAYERS))


def test_lower_layers_never_import_upper_ones():
    mods = module_names(PACKAGE)
    wrong = [f"{a} (layer {layer_of(a)}) imports {b} (layer {layer_of(b)}), line {line}"
             for a, b, line, _ in imports(PACKAGE) if b in mods and layer_of(b) > layer_of(a)]
    assert not wrong, "\n".join(wrong)


def test_only_nodes_imports_ros():
    wrong = [f"{a} imports {b}, line {line}" for a, b, line, _ in imports(PACKAGE)
             if b.split(".")[0] in ROS_MODULES and a.split(".")[1:2] != [ROS_PACKAGE]]
    assert not wrong, "\n".join(wrong)


def _write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root / "pkg"


def test_a_cycle_through_a_function_level_import_is_found(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/low/__init__.py": "",
        "pkg/low/a.py": "from pkg.high import b\n",
        "pkg/high/__init__.py": "",
        "pkg/high/b.py": "def f():\n    from pkg.low.a import thing\n    return thing\n",
    })
    assert find_cycle(module_graph(pkg)) == ["pkg.high.b", "pkg.low.a", "pkg.high.b"]


def test_a_relative_import_cycle_is_found_and_type_checking_imports_are_not_edges(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "from . import b\n",
        "pkg/b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import A\n",
    })
    assert find_cycle(module_graph(pkg)) is None
    (pkg / "b.py").write_text("import pkg.a\n")
    assert find_cycle(module_graph(pkg)) == ["pkg.a", "pkg.b", "pkg.a"]


@pytest.mark.parametrize(("statement", "ros_module"), [
    ("import rclpy", "rclpy"),
    ("from rclpy.node import Node", "rclpy"),
    ("def f():\n    from battery_predictor_msgs.msg import PackState", "battery_predictor_msgs"),
])
def test_the_ros_rule_sees_every_kind_of_import(tmp_path, statement, ros_module):
    pkg = _write(tmp_path, {"pkg/__init__.py": "", "pkg/core.py": statement + "\n", "pkg/nodes/n.py": "import rclpy\n"})
    found = {(a, b.split(".")[0]) for a, b, _, _ in imports(pkg) if b.split(".")[0] in ROS_MODULES}
    assert found == {("pkg.core", ros_module), ("pkg.nodes.n", "rclpy")}

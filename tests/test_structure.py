"""The package's layout, read from its own imports (``ast``, nothing is run).

Sub-packages stand on floors: one imports only those on lower floors (``LAYERS``), so a
reader can learn the package from the ground up; there is no import cycle between
modules; no command line shares its name with a library module; and no module reads
another module's private names.
"""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "torchrl_causal"
NAME = PACKAGE.name

#: The floors, ground first: a unit (a sub-package, or a module at the package root)
#: imports only units of lower floors. ``envs`` stands right above ``graphs`` (the envs are
#: pure simulation); ``experts`` (the planner, the experts, the walking skills and their
#: trainers) stands on ``envs`` and on ``experiment``, whose run-directory helpers the skill
#: trainers checkpoint with. The old module paths of what left ``envs`` (:data:`FORWARDS`)
#: stand on the top floor with the README's command paths.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors",),  # every refusal of the package derives from its root
    ("conf", "extras", "algorithms", "available", "command_line"),
    ("graphs", "progress", "compat"),
    ("envs",),
    ("modules", "objectives", "transforms", "data"),
    ("experiment",),
    ("experts",),
    ("trainers", "evaluation"),
    ("lifecycle",),
    ("cli",),
    ("train", "evaluate", "report", "status", "archive", "demo", "filmstrip", "strength_ablation", "forwards"),  # old paths
)
#: Modules kept at an old path, forwarding to where the code now lives (archived configs and
#: the results' commands name them): nothing in the package imports them.
FORWARDS = frozenset(f"{NAME}.envs.{name}" for name in ("planner", "experts", "locomotion", "locomotion_ppo"))
FLOOR = {unit: floor for floor, units in enumerate(LAYERS) for unit in units}


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _unit(module: str) -> str:
    if module in FORWARDS:
        return "forwards"
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _type_checking_lines(tree: ast.Module) -> set[int]:
    """Line numbers of the imports under ``if TYPE_CHECKING:`` (annotations only, no runtime edge)."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            lines.update(inner.lineno for stmt in node.body for inner in ast.walk(stmt) if hasattr(inner, "lineno"))
    return lines


def imports(path: Path) -> Iterator[tuple[str, tuple[str, ...], bool]]:
    """(imported module, names taken from it, at runtime?) for every import of ``path``,
    module-level or inside a function."""
    return iter(_imports(path))


@functools.cache
def _imports(path: Path) -> tuple[tuple[str, tuple[str, ...], bool], ...]:
    return tuple(_read_imports(path))


def _read_imports(path: Path) -> Iterator[tuple[str, tuple[str, ...], bool]]:
    tree = ast.parse(path.read_text())
    annotations_only = _type_checking_lines(tree)
    here = _module_name(path).split(".")
    package = here if path.name == "__init__.py" else here[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, (), node.lineno not in annotations_only
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            yield module, tuple(alias.name for alias in node.names), node.lineno not in annotations_only


SOURCES = sorted(PACKAGE.rglob("*.py"))


def _edges(runtime_only: bool = False) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a ``from package import name`` that names
    a submodule counts as importing that submodule)."""
    modules = {_module_name(path) for path in SOURCES}
    edges: dict[str, set[str]] = {}
    for path in SOURCES:
        targets = set()
        for module, names, runtime in imports(path):
            if not module.startswith(NAME) or (runtime_only and not runtime):
                continue
            submodules = {f"{module}.{name}" for name in names} & modules
            targets |= submodules or {module}
        edges[_module_name(path)] = targets - {_module_name(path)}
    return edges


def test_every_unit_has_a_floor() -> None:
    units = {_unit(_module_name(path)) for path in SOURCES} - {"__init__"}
    assert units <= set(FLOOR), f"place {sorted(units - set(FLOOR))} in LAYERS"


def _upward(edges: dict[str, set[str]]) -> list[str]:
    """The imports of ``edges`` that reach the importer's own floor or a higher one."""
    return sorted(
        f"{module} -> {target}"
        for module, targets in edges.items()
        for target in targets
        if _unit(module) != "__init__" and _unit(target) != _unit(module) and FLOOR.get(_unit(target), len(LAYERS)) >= FLOOR[_unit(module)]
    )


def test_upward_finds_an_import_from_a_lower_floor() -> None:
    edges = {
        f"{NAME}.trainers.bc": {f"{NAME}.experiment.builders", f"{NAME}.trainers.base"},
        f"{NAME}.evaluation.metrics": {f"{NAME}.trainers.base"},
    }
    assert _upward(edges) == [f"{NAME}.evaluation.metrics -> {NAME}.trainers.base"]


def test_no_sub_package_imports_one_above_it() -> None:
    assert not _upward(_edges()), _upward(_edges())


def test_forwards_are_modules_of_the_package() -> None:
    """Each old path of :data:`FORWARDS` is a file (a typo would exempt nothing)."""
    assert FORWARDS <= {_module_name(path) for path in SOURCES}


def test_envs_import_nothing_above_them_at_runtime() -> None:
    """What the envs import (their forwarding modules aside) reaches no unit above ``envs``:
    the package's ground is graphs and the envs, which know no expert, trainer or run."""
    edges = _edges(runtime_only=True)
    reached, todo = set(), [m for m in edges if _unit(m) == "envs"]
    while todo:
        module = todo.pop()
        for target in edges.get(module, ()):
            if target not in reached:
                reached.add(target)
                todo.append(target)
    above = sorted(t for t in reached if _unit(t) != "__init__" and FLOOR.get(_unit(t), 0) > FLOOR["envs"])
    assert not above, above


def test_evaluation_does_not_import_trainers() -> None:
    reached = {target for module, targets in _edges().items() if _unit(module) == "evaluation" for target in targets}
    assert not {t for t in reached if _unit(t) == "trainers"}


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import cycle (a list of modules, first repeated last), or None (iterative DFS)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    for root in sorted(edges):
        if root in state:
            continue
        path, stack = [root], [iter(sorted(edges[root]))]
        state[root] = 1
        while stack:
            nxt = next(stack[-1], None)
            if nxt is None:
                state[path.pop()] = 2
                stack.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            elif nxt not in state and nxt in edges:
                state[nxt] = 1
                path.append(nxt)
                stack.append(iter(sorted(edges[nxt])))
    return None


def test_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycle() -> None:
    """Between modules, at runtime (an import under ``TYPE_CHECKING`` is no edge)."""
    assert _cycle(_edges(runtime_only=True)) is None


def test_no_command_line_shares_a_name_with_a_library_module() -> None:
    commands = {path.stem for path in (PACKAGE / "cli").glob("*.py")} - {"__init__"}
    shims = {unit for unit in LAYERS[-1]}
    library = {path.stem for path in SOURCES if _unit(_module_name(path)) not in {"cli", *shims}}
    assert commands, "the cli/ folder holds the command lines"
    assert not commands & library, sorted(commands & library)


PRIVATE = re.compile(r"^_[^_]")


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_imports_another_modules_private_names(path: Path) -> None:
    """``from x import _name`` only within one sub-package (a package's private module,
    such as ``transforms/_layout.py``, serves its own package); TorchRL's private names
    only through ``compat.py``."""
    own = _unit(_module_name(path))
    taken = [
        f"{module}.{name}"
        for module, names, _ in imports(path)
        for name in names
        if PRIVATE.match(name)
        and not (module.startswith(NAME) and _unit(module) == own)
        and not (module.startswith("torchrl.") and path.name == "compat.py")
    ]
    assert not taken, taken


def _private_reads(source: str) -> list[str]:
    """The private attributes ``source`` reads (``x._name``) without defining them itself
    (as a function, class, or by assigning ``something._name``), and the private methods it
    reaches through ``super()`` that no two of its classes define (an override chaining to
    a base defined elsewhere: reading that base's private name)."""
    tree = ast.parse(source)
    own = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            own.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            own.add(node.attr)
    methods = [
        stmt.name
        for cls in ast.walk(tree)
        if isinstance(cls, ast.ClassDef)
        for stmt in cls.body
        if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef))
    ]
    return [
        ast.unparse(node)
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and PRIVATE.match(node.attr)
        and (node.attr not in own or (_is_super(node.value) and methods.count(node.attr) < 2))
    ]


def _is_super(node: ast.expr) -> bool:
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "super"


def test_private_reads_are_found() -> None:
    source = "class D:\n    def __init__(self):\n        self._pa = []\n\ndef f(g, v):\n    return g._pa, v._rank\n"
    assert _private_reads(source) == ["v._rank"]
    override = "class L(Loss):\n    def _hook(self):\n        return super()._hook()\n"
    assert _private_reads(override) == ["super()._hook"]
    local_base = "class B:\n    def _hook(self):\n        pass\n\nclass C(B):\n    def _hook(self):\n        super()._hook()\n"
    assert _private_reads(local_base) == []


#: Underscored names that are public API: a named tuple's methods (underscored so as not
#: to clash with its fields) and Hydra's instantiation key.
PUBLIC_UNDERSCORED = {"_asdict", "_replace", "_target_"}


@pytest.mark.parametrize("path", [path for path in SOURCES if path.name != "compat.py"], ids=lambda p: str(p.relative_to(PACKAGE)))
def test_private_names_of_libraries_and_other_modules_are_read_only_in_compat(path: Path) -> None:
    """TorchRL's (tensordict's, torch's, OmegaConf's) private names are read, and its
    private hooks overridden, only in ``compat.py``, which gives each a public name; no
    module reads a private name of another of the package's modules."""
    reads = [read for read in _private_reads(path.read_text()) if read.rsplit(".", 1)[-1] not in PUBLIC_UNDERSCORED]
    assert not reads, f"{reads}: wrap the library's private name in torchrl_causal/compat.py, or make ours public"


@pytest.mark.parametrize("path", sorted((PACKAGE / "graphs").glob("*.py")), ids=lambda p: p.name)
def test_graph_algorithms_read_diagrams_through_their_public_view(path: Path) -> None:
    """``criteria`` and ``adjustment`` search a diagram through ``CausalDiagram.indexed``,
    not its private fields: no module of ``graphs/`` reads a private name it does not define."""
    assert not _private_reads(path.read_text())

"""Where each public object of torchrl-causal is documented: its *home*, one page per object.

A name is public where a module lists it in ``__all__``; many objects are listed twice, by the
module that defines them and by the package that re-exports them
(``torchrl_causal.transforms.causal_window.CausalWindowTransform`` is also
``torchrl_causal.transforms.CausalWindowTransform``). Documented on both pages, every
unqualified reference to it would find two targets. Each object is therefore documented once,
under the shortest import path a user has for it, as TorchRL's reference does: the shallowest
module listing it that is its defining module or a package above that module. Objects are
matched by where they are *defined* (followed through ``from ... import`` statements in the
modules' source), so that two constants of equal value are not taken for one.

As a Sphinx extension this module also resolves a reference that names an object of the
package by another of its import paths (the defining module's, or a name as the docstring's own
module sees it) to the object's home, as Sphinx's ``:canonical:`` does for classes only.
References that name nothing importable still fail the build.

Examples:
    >>> homes = public_homes(documented_modules())
    >>> homes[("torchrl_causal.transforms.causal_window", "CausalWindowTransform")]
    'torchrl_causal.transforms'
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import sys
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any

PACKAGE = "torchrl_causal"

#: (defining module, name there): a key naming one object wherever it is imported.
Definition = tuple[str, str]


def _is_package(module: ModuleType) -> bool:
    return hasattr(module, "__path__")


@cache
def _bindings(module_name: str) -> frozenset[str]:
    """The names a module's top level binds itself (assignments, ``def``, ``class``), read
    from its source: where a constant, which has no ``__module__``, is defined."""
    module = importlib.import_module(module_name)
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    bound: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            bound.add(node.name)
        elif isinstance(node, ast.Assign):
            bound.update(target.id for target in node.targets if isinstance(target, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            bound.add(node.target.id)
    return frozenset(bound)


@cache
def _all_module_names() -> tuple[str, ...]:
    """Every module of the package, private and alias ones included."""
    root = importlib.import_module(PACKAGE)
    return (PACKAGE, *(info.name for info in pkgutil.walk_packages(root.__path__, PACKAGE + ".")))


def definition(module_name: str, name: str) -> Definition:
    """Where ``module_name.name`` is defined: a class's or function's ``__module__`` and
    ``__qualname__``; for a constant, the module of the package whose source binds that name
    to that very object (a re-export, eager or lazy, only refers to it). A name imported
    from another library is defined where it is imported."""
    value = getattr(importlib.import_module(module_name), name)
    if inspect.isclass(value) or inspect.isroutine(value):
        if getattr(value, "__module__", None) and "<locals>" not in getattr(value, "__qualname__", "<locals>"):
            return value.__module__, value.__qualname__
    if name in _bindings(module_name):
        return module_name, name
    for candidate in _all_module_names():
        module = importlib.import_module(candidate)
        if name in _bindings(candidate) and getattr(module, name, None) is value:
            return candidate, name
    return module_name, name


def is_alias_module(module: ModuleType) -> bool:
    """A module that only forwards names defined elsewhere: the old import paths kept for
    archived configs (``envs.planner`` -> ``experts.planner``) and the ``python -m
    torchrl_causal.<command>`` aliases. It gets no page of its own. (A package re-exports
    its modules' names by design: it is never an alias.)"""
    names = getattr(module, "__all__", None)
    return not _is_package(module) and bool(names) and all(definition(module.__name__, name)[0] != module.__name__ for name in names)


def documented_modules() -> list[ModuleType]:
    """The package's modules that get a page: every module but the private ones (a name
    part starting with ``_``) and the alias modules, in import-path order."""
    root = importlib.import_module(PACKAGE)
    modules = [root]
    for info in pkgutil.walk_packages(root.__path__, PACKAGE + "."):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        module = importlib.import_module(info.name)
        if not is_alias_module(module):
            modules.append(module)
    return sorted(modules, key=lambda module: module.__name__)


def _home_rank(exporter: str, defined_in: str) -> tuple[int, int, str]:
    """Smaller is a better home: the defining module or a package above it before any other
    exporter, then the shorter import path."""
    above = exporter == defined_in or defined_in.startswith(exporter + ".")
    return (0 if above else 1, exporter.count("."), exporter)


def public_homes(modules: list[ModuleType]) -> dict[Definition, str]:
    """The module whose page documents each object that one of ``modules`` lists in
    ``__all__``, keyed by the object's definition."""
    exporters: dict[Definition, list[str]] = {}
    for module in modules:
        for name in getattr(module, "__all__", ()):
            exporters.setdefault(definition(module.__name__, name), []).append(module.__name__)
    return {key: min(found, key=lambda exporter: _home_rank(exporter, key[0])) for key, found in exporters.items()}


def members_by_page(modules: list[ModuleType], homes: dict[Definition, str]) -> dict[str, dict[str, list[str]]]:
    """For each module page: ``documented``, the names of its ``__all__`` whose home it is
    (in ``__all__``'s order), and ``elsewhere``, the full home paths of the others (listed
    on the page as links)."""
    pages = {}
    for module in modules:
        documented, elsewhere = [], []
        for name in getattr(module, "__all__", ()):
            defined = definition(module.__name__, name)
            home = homes[defined]
            if home == module.__name__:
                documented.append(name)
            else:
                elsewhere.append(f"{home}.{name}")
        pages[module.__name__] = {"documented": documented, "elsewhere": elsewhere}
    return pages


def _lookup(path: str) -> tuple[str, list[str]] | None:
    """``path`` split into the longest importable module of the package and the attribute
    chain under it that exists, or None when it names nothing of the package."""
    if path != PACKAGE and not path.startswith(PACKAGE + "."):
        return None
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        module_name = ".".join(parts[:cut])
        try:
            target: Any = importlib.import_module(module_name)
        except ImportError:
            continue
        for attribute in parts[cut:]:
            if not hasattr(target, attribute):
                return None
            target = getattr(target, attribute)
        return module_name, parts[cut:]
    return None


def home_path(path: str, homes: dict[Definition, str]) -> str | None:
    """The documented path of the object ``path`` names through any of its import paths
    (``torchrl_causal.graphs.adjustment.windowed_backdoor`` ->
    ``torchrl_causal.graphs.windowed_backdoor``), or None when it names nothing public."""
    found = _lookup(path)
    if found is None or not found[1]:
        return None
    module_name, attributes = found
    owner = getattr(importlib.import_module(module_name), attributes[0])
    if inspect.isclass(owner) and len(attributes) > 1:
        # A member is documented with the class that defines it (``RouteChoiceEnv.config``
        # is ``ConfoundedEnv.config``): the first class of the MRO holding it.
        holder = next((cls for cls in owner.__mro__ if attributes[1] in vars(cls)), owner)
        module_name, attributes = holder.__module__, [holder.__qualname__, *attributes[1:]]
        if "." in holder.__qualname__ or module_name not in sys.modules:
            return None
    defined = definition(module_name, attributes[0])
    home = homes.get(defined)
    if home is None:
        return None
    return ".".join([home, defined[1], *attributes[1:]])


def _docstring_module(module_name: str, class_name: str | None) -> str:
    """The module whose namespace the docstring being resolved was written in: the one
    defining the class documented (its page may be a package's), else the page's module."""
    found = _lookup(f"{module_name}.{class_name}") if class_name else None
    if found is not None:
        target: Any = importlib.import_module(found[0])
        for attribute in found[1]:
            target = getattr(target, attribute)
        if inspect.isclass(target):
            return target.__module__
    return module_name


def _resolve_elsewhere(app: Any, env: Any, node: Any, contnode: Any) -> Any:
    """``missing-reference``: retry a reference into this package at its target's home,
    reading an unqualified name as the docstring's own module and class see it."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    homes = package_homes()
    candidates = [target]
    if not target.startswith(PACKAGE + "."):
        module_name = node.get("py:module") or ""
        class_name = node.get("py:class")
        written_in = _docstring_module(module_name, class_name) if module_name else ""
        if written_in:
            if class_name:
                candidates.append(f"{written_in}.{class_name.rpartition('.')[2]}.{target}")
            candidates.append(f"{written_in}.{target}")
    domain = env.domains["py"]
    for candidate in candidates:
        home = home_path(candidate, homes)
        if home is None or home == target:
            continue
        found = domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], home, node, contnode)
        if found is not None:
            return found
    return None


@cache
def package_homes() -> dict[Definition, str]:
    """:func:`public_homes` of :func:`documented_modules`, computed once per build."""
    return public_homes(documented_modules())


def setup(app: Any) -> dict[str, Any]:
    app.connect("missing-reference", _resolve_elsewhere)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

"""One tree of errors: every ``raise`` of the package raises a :class:`~torchrl_causal.errors.TorchRLCausalError`.

Read from the source (``ast``, nothing is run): each raised class is followed through the
package's class definitions, base by base, to ``TorchRLCausalError``. The few raises that are
no refusal of the library stand in :data:`ALLOWED`, each with its reason.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

import torchrl_causal.errors as errors

PACKAGE = Path(__file__).resolve().parents[1] / "torchrl_causal"
ROOT = "TorchRLCausalError"

#: ``(file, raised expression) -> why it is not a TorchRLCausalError``; ``*`` stands for any file.
ALLOWED: dict[tuple[str, str], str] = {
    # A command line's exit (its status and one line for the shell), not an error of the library.
    ("*", "SystemExit"): "exit",
    # An argparse type function must raise ArgumentTypeError: that is how argparse reports a bad flag
    # (OneLineParser turns it into one line).
    ("command_line.py", "argparse.ArgumentTypeError"): "argparse type protocol",
    ("experts/locomotion_ppo.py", "argparse.ArgumentTypeError"): "argparse type protocol",
    # A sequence protocol method that must raise TypeError (len() of a lazily computed adjacency).
    ("graphs/criteria.py", "TypeError"): "sequence protocol",
    # A module's __getattr__ must raise AttributeError: that is how Python looks names up.
    ("envs/__init__.py", "AttributeError"): "module attribute protocol",
    ("experts/__init__.py", "AttributeError"): "module attribute protocol",
    # An abstract hook that every subclass overrides: reaching it is a bug of the subclass.
    ("experts/policies.py", "NotImplementedError"): "abstract method",
    # A search invariant (marked `pragma: no cover`): reaching it is a bug of the algorithm.
    ("graphs/adjustment.py", "AssertionError"): "internal invariant",
    # A requested stop (a signal, a deadline) carried to the top, documented outside the tree.
    ("experiment/interrupts.py", "RunInterrupted"): "requested stop",
    ("trainers/base.py", "self._interrupted"): "requested stop (the RunInterrupted a signal left)",
    ("experts/locomotion_ppo.py", "RunInterrupted"): "requested stop (after the batch in flight and a save)",
}


def _raises() -> Iterator[tuple[str, int, str]]:
    """``(file, line, raised expression)`` for every ``raise X`` / ``raise X(...)`` of the package."""
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Raise) and node.exc is not None:
                raised = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                yield path.relative_to(PACKAGE).as_posix(), node.lineno, ast.unparse(raised)


def _definitions() -> tuple[dict[str, list[str]], dict[str, str]]:
    """The package's classes (name -> base names) and functions (name -> returned class name)."""
    classes: dict[str, list[str]] = {}
    returns: dict[str, str] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                assert node.name not in classes or not node.name.endswith("Error"), f"two error classes named {node.name}"
                classes[node.name] = [ast.unparse(base).rpartition(".")[2] for base in node.bases]
            elif isinstance(node, ast.FunctionDef) and node.returns is not None:
                returns[node.name] = ast.unparse(node.returns).strip("'\"")
    return classes, returns


CLASSES, RETURNS = _definitions()
RAISES = list(_raises())


def derives_from_root(name: str, classes: dict[str, list[str]] = CLASSES) -> bool:
    """Whether the package's class ``name`` has ``TorchRLCausalError`` among its ancestors."""
    seen, todo = set(), [name]
    while todo:
        current = todo.pop()
        if current == ROOT:
            return True
        if current not in seen:
            seen.add(current)
            todo.extend(classes.get(current, ()))
    return False


def test_the_walk_tells_the_tree_from_built_ins() -> None:
    classes = {"A": ["TorchRLCausalError"], "B": ["A", "ValueError"], "C": ["ValueError"]}
    assert derives_from_root("B", classes) and not derives_from_root("C", classes) and not derives_from_root("ValueError", classes)
    assert {"GraphError", "DatasetError", "InvalidValueError", "RenderingUnavailable"} <= {n for n in CLASSES if derives_from_root(n)}


def test_every_raise_is_a_refusal_of_the_tree_or_allowed() -> None:
    found = RAISES
    assert len(found) > 300, "the walk reaches the package's raises"
    wrong = []
    for file, line, raised in found:
        if (file, raised) in ALLOWED or ("*", raised) in ALLOWED:
            continue
        name = RETURNS.get(raised, raised)  # a function that builds the error: its return type
        if not derives_from_root(name):
            wrong.append(f"{file}:{line} raises {raised}")
    assert not wrong, "raise a TorchRLCausalError subclass (torchrl_causal/errors.py has one per built-in): " + "; ".join(wrong)


def test_every_allowed_raise_still_exists() -> None:
    """An allowance whose raise is gone is removed, so the list stays the short one it is."""
    present = {(file, raised) for file, _, raised in RAISES} | {("*", raised) for _, _, raised in RAISES}
    assert set(ALLOWED) <= present, sorted(set(ALLOWED) - present)


@pytest.mark.parametrize("name", errors.__all__)
def test_each_twin_is_caught_as_its_built_in_and_as_the_root(name: str) -> None:
    """``except ValueError`` (the built-in a refusal always raised) and ``except TorchRLCausalError`` both catch it."""
    error_class = getattr(errors, name)
    builtin = next((base for base in error_class.__mro__ if base.__module__ == "builtins" and base is not Exception), Exception)
    with pytest.raises(builtin) as caught:
        raise error_class("refused")
    assert isinstance(caught.value, errors.TorchRLCausalError) and (builtin is not Exception or name == "TorchRLCausalError")

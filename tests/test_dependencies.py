"""Every dependency is bounded to the versions the results were made with: each requirement
of ``pyproject.toml`` (runtime and extras) carries an upper bound no further than the next
major (next minor for 0.x) after the version ``constraints.txt`` pins, that pin satisfies it,
every third-party module the package imports is declared, and ``[all]`` holds every extra.
``.ci/wheel_check`` runs the same bound check on the built wheel's Requires-Dist."""

from __future__ import annotations

import ast
import importlib.util
import sys
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest
import tomllib
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
# A module imported to quiet a notice of a dependency's own dependency, not used otherwise.
TRANSITIVE = {"farama_notifications": "gymnasium"}


def _checker():
    spec = importlib.util.spec_from_file_location("requires_bounded", ROOT / ".ci" / "requires_bounded.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _requirements() -> list[Requirement]:
    lines = [*PROJECT["dependencies"], *(line for extra in PROJECT["optional-dependencies"].values() for line in extra)]
    return [Requirement(line) for line in lines if canonicalize_name(Requirement(line).name) != "torchrl-causal"]


def _pins() -> dict[str, Version]:
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            name, version = line.split("==")
            pins[canonicalize_name(name)] = Version(version)
    return pins


def test_the_checker_tells_bounded_from_unbounded():
    unbounded = _checker().unbounded
    assert unbounded(["mujoco>=3.1", "numpy", "tqdm>=4.60,<5", "minari[hdf5]==0.5.4", "x~=1.2", "torchrl-causal[video]"]) == [
        "mujoco>=3.1",
        "numpy",
    ]


def test_every_requirement_is_bounded_above():
    lines = [*PROJECT["dependencies"], *(line for extra in PROJECT["optional-dependencies"].values() for line in extra)]
    assert _checker().unbounded(lines) == []


def _next_release(pin: Version) -> Version:
    """The first version outside the pin's compatible range: next major, or next minor for 0.x."""
    return Version(f"0.{pin.minor + 1}") if pin.major == 0 else Version(f"{pin.major + 1}")


@pytest.mark.parametrize("requirement", _requirements(), ids=str)
def test_the_pinned_version_satisfies_it_and_the_bound_admits_no_new_major(requirement):
    pin = _pins().get(canonicalize_name(requirement.name))
    assert pin is not None, f"{requirement.name} is not pinned in constraints.txt"
    assert requirement.specifier.contains(pin, prereleases=True), f"constraints.txt's {pin} is outside {requirement}"
    assert not requirement.specifier.contains(_next_release(pin), prereleases=True), f"{requirement} admits {_next_release(pin)}"


def test_all_extra_holds_every_feature_extra():
    (own,) = [Requirement(line) for line in PROJECT["optional-dependencies"]["all"]]
    assert canonicalize_name(own.name) == "torchrl-causal"
    assert own.extras == set(PROJECT["optional-dependencies"]) - {"all", "test", "docs"}  # tools, not features


def _imported_modules() -> set[str]:
    modules = set()
    for file in (ROOT / "torchrl_causal").rglob("*.py"):
        for node in ast.walk(ast.parse(file.read_text())):
            if isinstance(node, ast.Import):
                modules |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules.add(node.module.split(".")[0])
    return modules - set(sys.stdlib_module_names) - {"torchrl_causal"}


def test_every_imported_third_party_module_is_declared():
    declared = {canonicalize_name(requirement.name) for requirement in _requirements()}
    distributions = packages_distributions()
    undeclared = {}
    for module in sorted(_imported_modules()):
        if module in TRANSITIVE:
            assert canonicalize_name(TRANSITIVE[module]) in declared
            continue
        names = {canonicalize_name(name) for name in distributions.get(module, [])}
        if not names:
            continue  # an extra's module that this venv lacks: the extras' own tests skip then
        if not names & declared:
            undeclared[module] = sorted(names)
    assert undeclared == {}, f"imported but not declared in pyproject.toml: {undeclared}"

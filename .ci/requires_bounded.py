"""Refuses a wheel (or a list of requirements) with a dependency that has no upper bound.

``python .ci/requires_bounded.py <wheel>`` reads the wheel's ``Requires-Dist`` lines (its
METADATA, what pip resolves from) and exits 1 naming every requirement, runtime or extra,
that a new major (or, for a 0.x release, a new minor) could satisfy: each must carry a ``<``,
``<=``, ``==`` or ``~=`` bound. A requirement on this project itself (the ``[all]`` extra's
``torchrl-causal[...]``) is exempt. ``tests/test_dependencies.py`` runs the same check on
``pyproject.toml``.
"""

from __future__ import annotations

import sys
import zipfile
from collections.abc import Iterable

from packaging.requirements import Requirement

PROJECT = "torchrl-causal"
UPPER_BOUNDING = ("<", "<=", "==", "~=", "===")


def unbounded(requirements: Iterable[str]) -> list[str]:
    """The requirements of ``requirements`` with no upper bound (this project's own excepted)."""
    found = []
    for line in requirements:
        requirement = Requirement(line)
        if requirement.name.lower().replace("_", "-") == PROJECT:
            continue
        if not any(spec.operator in UPPER_BOUNDING for spec in requirement.specifier):
            found.append(line)
    return found


def wheel_requirements(wheel: str) -> list[str]:
    """The ``Requires-Dist`` values of ``wheel``'s METADATA."""
    with zipfile.ZipFile(wheel) as archive:
        metadata = next(name for name in archive.namelist() if name.endswith(".dist-info/METADATA"))
        text = archive.read(metadata).decode()
    return [line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("Requires-Dist:")]


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python .ci/requires_bounded.py <wheel>", file=sys.stderr)
        return 2
    requirements = wheel_requirements(argv[0])
    if not requirements:
        print(f"error: {argv[0]} declares no Requires-Dist", file=sys.stderr)
        return 1
    if missing := unbounded(requirements):
        print(f"error: {argv[0]} has dependencies without an upper bound: {'; '.join(missing)}", file=sys.stderr)
        return 1
    print(f"{len(requirements)} requirements of {argv[0]}, each bounded above")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

"""The command lines, each a thin ``main`` over library functions; no command line imports
another. ``torchrl-causal <command> [args]`` (the console script),
``python -m torchrl_causal.cli <command> [args]`` and ``python -m torchrl_causal.<command> [args]``
run the same ``main``.

Commands: ``train`` (Hydra overrides: ``env=rovermaze_u algo=bc ...``), ``evaluate``,
``report``, ``status``, ``archive``, ``demo``, ``filmstrip`` and ``strength_ablation``
(``key=value`` arguments; each prints its usage on a missing or unknown key). Each answers
``--help`` with its options, their defaults and an example; ``help <command>`` does too.

Examples:
    >>> main(["help"])  # doctest: +ELLIPSIS
    usage: torchrl-causal <command> [args]
    commands: train, evaluate, report, status, archive, demo, filmstrip, strength_ablation
    ...
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

__all__ = ["COMMANDS", "main"]

#: The command lines, in the order a new user meets them — the registry of ``torchrl-causal
#: <command>``, one line each (``cli/<command>.py`` holds its ``main``).
COMMANDS = (
    "train",
    "evaluate",
    "report",
    "status",
    "archive",
    "demo",
    "filmstrip",
    "strength_ablation",
)

USAGE = (
    "usage: torchrl-causal <command> [args]\n"
    f"commands: {', '.join(COMMANDS)}\n"
    "the same: python -m torchrl_causal.cli <command> [args], python -m torchrl_causal.<command> [args]\n"
    "torchrl-causal <command> --help (or: torchrl-causal help <command>) lists a command's options and defaults\n"
    "e.g. torchrl-causal train env=rovermaze_u algo=bc; torchrl-causal evaluate run_dir=<dir>"
)


def main(argv: Sequence[str] | None = None) -> None:
    """Runs ``argv[0]``'s command line on the rest of ``argv`` (default: ``sys.argv[1:]``).

    Raises:
        SystemExit: with the usage, when no command or an unknown one is named.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] in (["help"], ["-h"], ["--help"]) and len(args) == 2 and args[1] in COMMANDS:
        args = [args[1], "--help"]  # help <command>: that command's help
    if not args or args[0] in ("help", "-h", "--help"):
        print(USAGE)
        return
    command, rest = args[0], args[1:]
    if command not in COMMANDS:
        raise SystemExit(f"unknown command {command!r}\n{USAGE}")
    module = importlib.import_module(f"torchrl_causal.cli.{command}")
    if command == "train":  # Hydra's main reads its overrides from sys.argv
        sys.argv = [f"torchrl-causal {command}", *rest]
        module.entry_point()
    else:
        module.main(rest)

"""The command lines' argument parsing, at its old path: it lives in :mod:`torchrl_causal.command_line`
(below :mod:`torchrl_causal.experts`, whose skill trainers parse their ``--flags`` with it too)."""

from torchrl_causal import command_line as _moved
from torchrl_causal.command_line import *  # noqa: F403  (every public name, as before the move)

__all__ = list(_moved.__all__)

"""Exceptions raised by the causal graph engine."""

from __future__ import annotations

from collections.abc import Hashable, Sequence

__all__ = ["GraphError", "NotImitableError", "BoundedInfluenceError"]


class GraphError(ValueError):
    """Malformed causal input: a directed cycle, an unknown variable, a negative lag or k,
    duplicate names, an observed set that is not a subset of the variables, ..."""


class BoundedInfluenceError(GraphError):
    """Assumption 1(i) (k-bounded influence) fails for the requested window size, so the
    windowed adjustment of Theorem 1 would not be guaranteed valid."""


class NotImitableError(ValueError):
    """No sequential pi-backdoor adjustment exists (Definition 2 cannot be met).

    Attributes:
        actions: the action nodes for which no admissible set exists, in temporal order.
        witness: a path (tuple of nodes) that stays open for one of them under the largest
            candidate adjustment (every observed ancestor of the reward before the action).
    """

    def __init__(self, message: str, actions: Sequence[Hashable] = (), witness: Sequence[Hashable] = ()) -> None:
        super().__init__(message)
        self.actions = tuple(actions)
        self.witness = tuple(witness)

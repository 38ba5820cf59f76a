"""Exceptions raised by the causal graph engine.

A refusal to give an adjustment says which step failed, each with its own error:

* :class:`NotImitableError`: no family of sets meets Definition 2 (FindOX leaves out an
  action); ``witness`` is a certificate path that no choice of sets can block.
* :class:`BoundedInfluenceError`: Assumption 1(i) fails for the requested ``k``; ``chain``
  is the path that makes an extended parent too early.
* :class:`WindowConstructionError`: the windowed construction fails at a horizon:
  ``witness`` stays open there under every window tried, although the diagram itself may
  be imitable (``exact_adjustment`` may still succeed).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

from torchrl_causal.errors import TorchRLCausalError

__all__ = ["BoundedInfluenceError", "GraphError", "NotImitableError", "WindowConstructionError", "WindowSizeError", "check_window_size"]


class GraphError(TorchRLCausalError, ValueError):
    """Base of the graph engine's errors; raised itself on malformed causal input: a directed
    cycle, an unknown variable, a negative lag or k, duplicate names, an observed set that is
    not a subset of the variables, ... Its subclasses are the refusals listed above."""


class BoundedInfluenceError(GraphError):
    """Assumption 1(i) (k-bounded influence) fails for the requested window size, so the
    windowed adjustment of Theorem 1 would not be guaranteed valid.

    Attributes:
        k: the window size asked for.
        required_k: the smallest sufficient k, or None when no k suffices.
        chain: the path in the latent projection that makes an extended parent so early.
    """

    def __init__(self, message: str, k: int | None = None, required_k: int | None = None, chain: Sequence[Hashable] = ()) -> None:
        super().__init__(message)
        self.k = k
        self.required_k = required_k
        self.chain = tuple(chain)


class NotImitableError(GraphError):
    """No sequential pi-backdoor adjustment exists (Definition 2 cannot be met).

    Attributes:
        actions: the action nodes for which no admissible set exists, in temporal order.
        witness: a certificate: a path from one of them to the reward that stays open
            whatever the sets (empty when no single path shows it).
    """

    def __init__(self, message: str, actions: Sequence[Hashable] = (), witness: Sequence[Hashable] = ()) -> None:
        super().__init__(message)
        self.actions = tuple(actions)
        self.witness = tuple(witness)


class WindowConstructionError(NotImitableError):
    """Algorithm 1's windowed construction fails: no window tried meets Definition 2 at
    :attr:`horizon`, though the proxy is imitable and Assumption 1 holds.

    It derives from :class:`NotImitableError` only so that code that catches every refusal
    of ``windowed_adjustment`` that way keeps working; it does not say that no adjustment
    exists (catch it first to tell the two apart).

    Attributes:
        actions: the actions whose Definition-2 check fails at :attr:`horizon`.
        witness: an open path at :attr:`horizon` under the window Algorithm 1 built.
        horizon: the horizon of the unrolled diagram the failure was found at.
    """

    def __init__(self, message: str, actions: Sequence[Hashable] = (), witness: Sequence[Hashable] = (), horizon: int = 0) -> None:
        super().__init__(message, actions, witness)
        self.horizon = horizon


class WindowSizeError(GraphError):
    """A window of ``k`` lags asked for an env whose episodes last ``horizon <= k`` steps: the
    lags past ``horizon - 1`` would only ever hold padding, and each one adds a copy of the
    state to every observation.

    Attributes:
        k: the window size asked for.
        horizon: the env's horizon.
    """

    def __init__(self, k: int, horizon: int) -> None:
        super().__init__(
            f"window size k={k} must be < the env's horizon={horizon}: a window reaches at most horizon - 1 "
            "steps back (each lag adds a copy of the state to every observation)"
        )
        self.k = k
        self.horizon = horizon


def check_window_size(k: object) -> int:
    """``k`` when it is a window size (an int >= 0; a bool is not one): the one rule every
    API that takes ``k`` checks where ``k`` enters it (the graph engine, :class:`~torchrl_causal.graphs.AdjustmentWindow`,
    the window transform and its replay encoder). A config's ``window.k`` is checked by the
    config schema, and against the horizon (:class:`WindowSizeError`) where an env is known.

    Raises:
        GraphError: naming ``k``.

    Examples:
        >>> check_window_size(3)
        3
        >>> check_window_size(-1)
        Traceback (most recent call last):
        ...
        torchrl_causal.graphs.errors.GraphError: window size k must be an int >= 0, got -1
    """
    if isinstance(k, bool) or not isinstance(k, int) or k < 0:
        raise GraphError(f"window size k must be an int >= 0, got {k!r}")
    return k

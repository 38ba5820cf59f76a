"""The adjustment window: the one object through which causal knowledge enters training.

:func:`~torchrl_causal.graphs.windowed_adjustment` computes it from a time-slice
template; :class:`~torchrl_causal.transforms.CausalWindowTransform` applies it to
TensorDicts. It is plain data (no torch), JSON-serialisable through :meth:`to_dict`, so
that a saved policy reloads with exactly the encoding it was trained on.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from torchrl_causal.errors import InvalidValueError
from torchrl_causal.graphs.errors import check_window_size

Node = Hashable

__all__ = ["AdjustmentWindow"]


def _node_to_json(node: Node) -> Any:
    return list(node) if isinstance(node, tuple) else node


def _node_from_json(node: Any) -> Node:
    return tuple(node) if isinstance(node, list) else node


@dataclass(frozen=True)
class AdjustmentWindow:
    """Which observed variables, at which lags, the imitator may condition on.

    Lags count steps back from the current step ``t`` (``0`` is the current step). State
    variables carry lags ``0..k``; the action carries ``1..k`` (previous actions), as in
    the paper's Algorithm 2 encoder.

    Attributes:
        k: window size (number of past steps the encoding reaches back).
        action: name of the action variable.
        lags: admissible variable -> ascending tuple of lags. Its iteration order (the
            template's variable order, the action last) is the order in which
            :class:`~torchrl_causal.transforms.CausalWindowTransform` concatenates
            features: variable by variable, and within a variable by increasing lag.
        excluded: observed variables left out of every adjustment set (e.g. the compass W).
        exact: ``True`` when the per-step sets provably satisfy the sequential
            pi-backdoor criterion (Definition 2); ``False`` for relaxed or non-causal
            windows.
        witnesses: paths (tuples of nodes ``(var, t)`` or ``"Y"``) that stay open under
            this window in the unrolled diagrams it was checked on; empty when ``exact``.
        observed: every variable the imitator observes, in template order.
        lags_beyond_k: template edges ``(kind, src, dst, lag)`` (kind ``"directed"`` or
            ``"bidirected"``) whose lag exceeds ``k``, so that their far end lies outside
            the window.

    Examples:
        >>> w = AdjustmentWindow(k=2, action="X", lags={"P": (0, 1, 2), "X": (1, 2)},
        ...                      excluded=frozenset({"W"}), exact=False,
        ...                      observed=("P", "W", "X"))
        >>> sorted(w.adjustment_set(1))
        [('P', 0), ('P', 1), ('X', 0)]
        >>> AdjustmentWindow.from_dict(w.to_dict()) == w
        True
        >>> w.past_only().lags
        {'P': (1, 2), 'X': (1, 2)}
        >>> w.non_causal_twin().lags
        {'P': (0, 1, 2), 'W': (0, 1, 2), 'X': (1, 2)}
    """

    k: int
    action: str
    lags: Mapping[str, tuple[int, ...]]
    excluded: frozenset[str] = frozenset()
    exact: bool = False
    witnesses: tuple[tuple[Node, ...], ...] = ()
    observed: tuple[str, ...] = field(default=())
    lags_beyond_k: tuple[tuple[str, str, str, int], ...] = ()

    def __post_init__(self) -> None:
        check_window_size(self.k)
        for var, var_lags in self.lags.items():
            if list(var_lags) != sorted(set(var_lags)) or any(lag < 0 or lag > self.k for lag in var_lags):
                raise InvalidValueError(f"lags of {var!r} must be strictly increasing within 0..{self.k}, got {var_lags!r}")
            if var == self.action and 0 in var_lags:
                raise InvalidValueError(f"the action {var!r} cannot be conditioned on at lag 0 (it is being chosen)")
        object.__setattr__(self, "lags", {var: tuple(v) for var, v in self.lags.items()})
        object.__setattr__(self, "excluded", frozenset(self.excluded))
        object.__setattr__(self, "lags_beyond_k", tuple(tuple(edge) for edge in self.lags_beyond_k))

    @property
    def variables(self) -> tuple[str, ...]:
        """Admissible variables in encoding order."""
        return tuple(self.lags)

    def adjustment_set(self, t: int) -> frozenset[tuple[str, int]]:
        """The set ``Z_t`` as nodes ``(var, tau)``, clipped at the episode start (tau >= 0)."""
        if t < 0:
            raise InvalidValueError(f"timestep must be >= 0, got {t}")
        return frozenset((var, t - lag) for var, var_lags in self.lags.items() for lag in var_lags if t - lag >= 0)

    def non_causal_twin(self) -> AdjustmentWindow:
        """The window-matched non-causal baseline of this window.

        Every observed variable, the excluded ones (e.g. the compass ``W``) included, at
        the lags this window gives its state variables (their union), and the action at
        lags ``1..k``; nothing excluded, ``exact=False``, no witnesses. It conditions on
        the same stretch of history as this window, so comparing the two separates the
        effect of excluding variables from the effect of using a window.

        Raises:
            ValueError: if :attr:`observed` is empty (the twin needs to know what the
                imitator observes).
        """
        if not self.observed:
            raise InvalidValueError("the non-causal twin needs window.observed to know which variables the imitator sees")
        state_lags = tuple(sorted({lag for var, lags in self.lags.items() if var != self.action for lag in lags}))
        action_lags = tuple(range(1, self.k + 1))
        lags = {var: action_lags if var == self.action else state_lags for var in self.observed}
        return replace(self, lags={var: lags for var, lags in lags.items() if lags}, excluded=frozenset(), exact=False, witnesses=())

    def past_only(self) -> AdjustmentWindow:
        """This window without lag 0: only steps before the current one (lags ``1..k``).

        The reading of the paper's Algorithm 1 line 14 that conditions on past steps only.
        Variables left with no lag are dropped. The smaller sets have not been checked
        against the sequential pi-backdoor criterion, so the result has ``exact=False``
        and no witnesses (a window without lag 0 is returned unchanged).
        """
        past = {var: tuple(lag for lag in lags if lag > 0) for var, lags in self.lags.items()}
        if past == dict(self.lags):
            return self
        return replace(self, lags={var: lags for var, lags in past.items() if lags}, exact=False, witnesses=())

    def without(self, variables: Iterable[str]) -> AdjustmentWindow:
        """This window with ``variables`` left out at every lag (an ablation, not an adjustment).

        Dropping the action removes the previous actions from the encoding: a history of
        the demonstrator's own actions lets an imitator predict the next one by repeating
        the last, a shortcut its own actions do not offer at rollout (the "copycat"
        problem of Wen et al., NeurIPS 2020). Dropped state variables join
        :attr:`excluded`. The smaller sets have not been checked against the sequential
        pi-backdoor criterion, so the result has ``exact=False`` and no witnesses (an
        empty ``variables`` returns the window unchanged).

        Raises:
            ValueError: if a variable is not in the window (:attr:`lags`).

        Examples:
            >>> w = AdjustmentWindow(k=2, action="X", lags={"P": (0, 1, 2), "X": (1, 2)})
            >>> w.without(["X"]).lags
            {'P': (0, 1, 2)}
        """
        dropped = set(variables)
        if not dropped:
            return self
        missing = sorted(dropped - set(self.lags))
        if missing:
            raise InvalidValueError(f"cannot drop {missing}: not in the window, whose variables are {list(self.lags)}")
        return replace(
            self,
            lags={var: lags for var, lags in self.lags.items() if var not in dropped},
            excluded=self.excluded | (dropped - {self.action}),
            exact=False,
            witnesses=(),
        )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable description; :meth:`from_dict` inverts it exactly."""
        return {
            "k": self.k,
            "action": self.action,
            "lags": {var: list(v) for var, v in self.lags.items()},
            "excluded": sorted(self.excluded),
            "exact": self.exact,
            "witnesses": [[_node_to_json(n) for n in path] for path in self.witnesses],
            "observed": list(self.observed),
            # only when there are some, so that descriptions saved before the field existed match
            **({"lags_beyond_k": [list(edge) for edge in self.lags_beyond_k]} if self.lags_beyond_k else {}),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AdjustmentWindow:
        missing = {"k", "action", "lags"} - set(data)
        if missing:
            raise InvalidValueError(f"adjustment window description lacks {sorted(missing)}")
        return cls(
            k=int(data["k"]),
            action=str(data["action"]),
            lags={str(var): tuple(int(x) for x in v) for var, v in data["lags"].items()},
            excluded=frozenset(data.get("excluded", ())),
            exact=bool(data.get("exact", False)),
            witnesses=tuple(tuple(_node_from_json(n) for n in path) for path in data.get("witnesses", ())),
            observed=tuple(data.get("observed", ())),
            lags_beyond_k=tuple(tuple(edge) for edge in data.get("lags_beyond_k", ())),
        )

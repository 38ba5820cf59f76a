"""Time-slice templates: one step of a time-homogeneous SCM, unrolled on demand."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Literal

from torchrl_causal.errors import InvalidTypeError

from .diagram import CausalDiagram
from .errors import GraphError

__all__ = ["TimeSliceTemplate", "REWARD"]

#: The node that stands for the single terminal (latent) reward in unrolled diagrams.
REWARD = "Y"

Edge = tuple[str, str, int]


def _check_lag(lag: object, what: str) -> int:
    if isinstance(lag, bool) or not isinstance(lag, int):
        raise GraphError(f"lag of {what} must be an int, got {lag!r}")
    if lag < 0:
        raise GraphError(f"lag of {what} must be >= 0, got {lag}")
    return lag


@dataclass(frozen=True)
class TimeSliceTemplate:
    """One time slice of a time-homogeneous causal diagram.

    Args:
        variables: variable names, in the order used for encodings (each is one
            TensorDict key of the env).
        action: the action variable (the imitator's decision at each step).
        observed: the variables the imitator observes (the action must be one of them);
            the others are latent to the imitator (the expert may still read them).
        directed: triples ``(src, dst, lag)``: ``src`` at ``t - lag`` -> ``dst`` at ``t``.
        bidirected: triples ``(a, b, lag)``: ``a`` at ``t - lag`` <-> ``b`` at ``t``.
        reward_parents: variables with an edge ``v -> Y`` into the terminal reward.
        reward_bidirected: variables with a bidirected edge ``v <-> Y``.
        reward_slices: ``"all"`` attaches the reward edges at every slice where the
            variable exists; ``"last"`` only at its last one (states at ``H``, the action
            at ``H - 1``).

    Within a slice the states come first (in a topological order of the lag-0 edges that
    follows ``variables``) and the action last: it is chosen after observing the current
    state, so it may not have lag-0 children.

    Raises:
        GraphError: on duplicate names, a variable named ``"Y"`` (the reward), an action that is not a variable or not observed,
            an observed set that is not a subset of the variables, an edge naming an
            unknown variable, a negative or non-int lag, a lag-0 cycle or self-loop, or an
            unknown ``reward_slices``.

    Examples:
        >>> tpl = TimeSliceTemplate(
        ...     variables=("Z", "O", "W", "X"), action="X", observed=("Z", "W", "X"),
        ...     directed=[("Z", "X", 0), ("O", "X", 0), ("O", "W", 0), ("Z", "Z", 1)],
        ...     reward_parents=("Z", "X"), reward_bidirected=("W",), reward_slices="last")
        >>> tpl.latent
        ('O',)
        >>> g = tpl.unroll(2)
        >>> sorted(g.parents("Y"))
        [('X', 1), ('Z', 2)]
        >>> g.nodes[:4]
        (('Z', 0), ('O', 0), ('W', 0), ('X', 0))
    """

    variables: tuple[str, ...]
    action: str
    observed: tuple[str, ...]
    directed: tuple[Edge, ...]
    bidirected: tuple[Edge, ...] = ()
    reward_parents: tuple[str, ...] = ()
    reward_bidirected: tuple[str, ...] = ()
    reward_slices: Literal["all", "last"] = "all"
    #: the slice's variables in a topological order of the lag-0 edges, states first (derived).
    slice_order: tuple[str, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        variables = tuple(self.variables)
        if isinstance(self.variables, str):
            raise GraphError(f"variables must be a sequence of names, got the string {self.variables!r}")
        seen: set[str] = set()
        for v in variables:
            if not isinstance(v, str) or not v:
                raise GraphError(f"variable names must be non-empty strings, got {v!r}")
            if v in seen:
                raise GraphError(f"duplicate variable name {v!r}")
            if v == REWARD:
                raise GraphError(f"the variable name {REWARD!r} is reserved for the terminal reward node")
            seen.add(v)
        if not isinstance(self.action, str) or self.action not in seen:
            raise GraphError(f"action {self.action!r} is not among the variables {variables}")
        observed_in = set(self._names(self.observed, "observed"))
        if self.action not in observed_in:
            raise GraphError(f"the action {self.action!r} must be observed (it is in every demonstration)")
        directed = self._edges(self.directed, "directed", seen)
        bidirected = self._edges(self.bidirected, "bidirected", seen)
        for src, dst, lag in directed:
            if lag == 0 and src == self.action:
                raise GraphError(
                    f"the action {self.action!r} cannot cause {dst!r} in its own slice (edge lag 0); "
                    "its effects start at the next slice (lag >= 1)"
                )
        for a, b, lag in bidirected:
            if lag == 0 and a == b:
                raise GraphError(f"bidirected self-loop on {a!r} at lag 0")
        reward_parents = self._names(self.reward_parents, "reward_parents", seen)
        reward_bidirected = self._names(self.reward_bidirected, "reward_bidirected", seen)
        if self.reward_slices not in ("all", "last"):
            raise GraphError(f"reward_slices must be 'all' or 'last', got {self.reward_slices!r}")
        set_ = object.__setattr__
        set_(self, "variables", variables)
        set_(self, "observed", tuple(v for v in variables if v in observed_in))
        set_(self, "directed", directed)
        set_(self, "bidirected", bidirected)
        set_(self, "reward_parents", reward_parents)
        set_(self, "reward_bidirected", reward_bidirected)
        set_(self, "slice_order", self._slice_order())

    def _names(self, names: Iterable[str], what: str, known: set[str] | None = None) -> tuple[str, ...]:
        if isinstance(names, str):
            raise GraphError(f"{what} must be a collection of variable names, got the string {names!r}")
        known = set(self.variables) if known is None else known
        result = []
        for v in names:
            if not isinstance(v, str) or v not in known:
                raise GraphError(f"{what} names {v!r}, which is not a variable ({sorted(known)})")
            if v not in result:
                result.append(v)
        return tuple(result)

    @staticmethod
    def _edges(edges: Iterable[Edge], what: str, known: set[str]) -> tuple[Edge, ...]:
        result: list[Edge] = []
        for edge in edges:
            try:
                a, b, lag = edge
            except (TypeError, ValueError):
                raise GraphError(f"a {what} edge must be a triple (src, dst, lag), got {edge!r}") from None
            for v in (a, b):
                if not isinstance(v, str) or v not in known:
                    raise GraphError(f"{what} edge {edge!r} names unknown variable {v!r}")
            triple = (a, b, _check_lag(lag, f"{what} edge {edge!r}"))
            if triple not in result:
                result.append(triple)
        return tuple(result)

    def _slice_order(self) -> tuple[str, ...]:
        """A topological order of the lag-0 edges, states first, ties broken by ``variables``."""
        position = {v: i for i, v in enumerate(self.variables)}
        parents: dict[str, set[str]] = {v: set() for v in self.variables}
        for src, dst, lag in self.directed:
            if lag == 0:
                parents[dst].add(src)
        order: list[str] = []
        remaining = [v for v in self.variables if v != self.action] + [self.action]
        while remaining:
            ready = [v for v in remaining if not (parents[v] - set(order))]
            if not ready:
                # every remaining variable waits on a remaining parent: walk parents to a repeat
                walk = [remaining[0]]
                while walk.count(walk[-1]) == 1:
                    walk.append(min(parents[walk[-1]] - set(order), key=position.__getitem__))
                cycle = walk[walk.index(walk[-1]) :][::-1]
                raise GraphError(f"lag-0 edges form a directed cycle: {' -> '.join(cycle)}")
            nxt = min(ready, key=lambda v: (v == self.action, position[v]))
            order.append(nxt)
            remaining.remove(nxt)
        return tuple(order)

    # ------------------------------------------------------------------ derived facts
    @property
    def latent(self) -> tuple[str, ...]:
        """Variables latent to the imitator, in template order."""
        return tuple(v for v in self.variables if v not in self.observed)

    @property
    def states(self) -> tuple[str, ...]:
        """Every variable except the action, in template order."""
        return tuple(v for v in self.variables if v != self.action)

    @property
    def max_lag(self) -> int:
        return max((lag for *_, lag in self.directed + self.bidirected), default=0)

    def last_slice(self, var: str, horizon: int) -> int:
        """The last timestep at which ``var`` exists in ``unroll(horizon)``."""
        return horizon - 1 if var == self.action else horizon

    def reward_ancestors(self) -> frozenset[str]:
        """Variables some instance of which is an ancestor of the reward once the horizon is
        long enough (ancestry in the summary graph, lags ignored)."""
        parents: dict[str, set[str]] = {v: set() for v in self.variables}
        for src, dst, _ in self.directed:
            parents[dst].add(src)
        found = set(self.reward_parents)
        stack = list(found)
        while stack:
            for p in parents[stack.pop()]:
                if p not in found:
                    found.add(p)
                    stack.append(p)
        return frozenset(found)

    def replace(self, **changes: object) -> TimeSliceTemplate:
        """A copy with some constructor arguments changed (validated again)."""
        fields = {
            name: getattr(self, name)
            for name in (
                "variables",
                "action",
                "observed",
                "directed",
                "bidirected",
                "reward_parents",
                "reward_bidirected",
                "reward_slices",
            )
        }
        unknown = set(changes) - set(fields)
        if unknown:
            raise InvalidTypeError(f"unknown template fields {sorted(unknown)}")
        fields.update(changes)
        return TimeSliceTemplate(**fields)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ unrolling
    def unroll(self, horizon: int) -> CausalDiagram:
        """The diagram over ``(var, t)`` (states ``t = 0..H``, actions ``t = 0..H-1``) plus ``"Y"``.

        Edges whose source would lie before ``t = 0`` (or at a slice where the variable does
        not exist) are dropped: the episode starts at ``t = 0``. The topological order is
        by timestep, then by :attr:`slice_order`, with ``"Y"`` last.
        """
        if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
            raise GraphError(f"horizon must be an int >= 1, got {horizon!r}")
        last = {v: self.last_slice(v, horizon) for v in self.variables}
        # Slices hold slice_order (the action last, absent from slice H), so (v, t) sits at
        # t * width + slot[v] and Y last.
        width = len(self.slice_order)
        slot = {v: i for i, v in enumerate(self.slice_order)}
        order: list[object] = [(v, t) for t in range(horizon + 1) for v in self.slice_order if t <= last[v]]
        order.append(REWARD)
        y = len(order) - 1
        directed = [
            ((t - lag) * width + slot[src], t * width + slot[dst])
            for src, dst, lag in self.directed
            for t in range(lag, last[dst] + 1)
            if t - lag <= last[src]
        ]
        bidirected = [
            ((t - lag) * width + slot[a], t * width + slot[b])
            for a, b, lag in self.bidirected
            for t in range(lag, last[b] + 1)
            if t - lag <= last[a]
        ]

        def slices(v: str) -> range:
            return range(last[v], last[v] + 1) if self.reward_slices == "last" else range(last[v] + 1)

        directed += [(t * width + slot[v], y) for v in self.reward_parents for t in slices(v)]
        bidirected += [(t * width + slot[v], y) for v in self.reward_bidirected for t in slices(v)]
        latent = [t * width + slot[v] for v in self.latent for t in range(last[v] + 1)]
        return CausalDiagram.from_indices(order, directed, bidirected, latent)

"""The sequential pi-backdoor criterion (Definition 2) and Kumor et al.'s FindOX.

Everything here runs on the integer adjacency of a :class:`CausalDiagram` and never
materialises a latent projection: on unrolled diagrams with a persistent hidden variable
the projection has a quadratic number of bidirected edges, whereas the searches below
stay linear per query.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field

from .diagram import CausalDiagram, _ancestor_ids, _find_open_path
from .errors import GraphError

Node = Hashable

__all__ = ["BackdoorReport", "sequential_pi_backdoor", "find_ox"]


@dataclass(frozen=True)
class BackdoorReport:
    """The outcome of :func:`sequential_pi_backdoor`.

    Attributes:
        holds: whether every action meets Definition 2.
        reasons: action -> ``"not_ancestor"`` (condition 2: the action is no ancestor of
            the reward in the manipulated graph), ``"separated"`` (condition 1) or
            ``"open_path"`` (neither).
        witnesses: failing action -> an open path from it to the reward in
            ``(G'_t)_{X_t}`` given its adjustment set.
    """

    holds: bool
    reasons: Mapping[Node, str]
    witnesses: Mapping[Node, tuple[Node, ...]] = field(default_factory=dict)

    @property
    def failing(self) -> tuple[Node, ...]:
        """The actions that violate Definition 2, in temporal order."""
        return tuple(self.witnesses)


def _action_ids(diagram: CausalDiagram, actions: Iterable[Node]) -> list[int]:
    ids = diagram._ids(actions)
    hidden = [diagram._nodes[i] for i in ids if i in diagram._latent]
    if hidden:
        raise GraphError(f"actions must be observed nodes, got latent {hidden}")
    return sorted(ids, key=diagram._rank.__getitem__)


class _ManipulatedGraph:
    """``G'_t`` built incrementally, latest action first.

    Going backwards in time, each action in turn becomes a "future" action: it loses every
    incoming edge (directed and bidirected: under ``do(pi)`` it responds to its adjustment
    set alone) and gets its set as parents. Each step costs the degree of one action, so
    checking all ``H`` actions costs ``H`` searches and no graph copies.
    """

    def __init__(self, diagram: CausalDiagram) -> None:
        self.pa = [list(p) for p in diagram._pa]
        self.ch = [list(c) for c in diagram._ch]
        self.sp = [list(s) for s in diagram._sp]

    def make_future(self, action: int, adjustment: Iterable[int]) -> None:
        pa, ch, sp = self.pa, self.ch, self.sp
        for p in pa[action]:
            ch[p].remove(action)
        for s in sp[action]:
            sp[s].remove(action)
        pa[action] = list(adjustment)
        sp[action] = []
        for z in pa[action]:
            ch[z].append(action)

    def check(self, x: int, z: set[int], reward: int) -> tuple[str, list[int] | None]:
        """Definition 2 for ``x`` (every later action already made future)."""
        pa, ch, sp = self.pa, self.ch, self.sp
        if reward not in _ancestor_ids(ch, [x]):
            return "not_ancestor", None
        children, ch[x] = ch[x], []
        for c in children:
            pa[c].remove(x)
        try:
            path = _find_open_path(
                pa, ch, sp, [x], z.__contains__, _ancestor_ids(pa, z).__contains__, reward.__eq__
            )
        finally:
            ch[x] = children
            for c in children:
                pa[c].append(x)
        return ("separated", None) if path is None else ("open_path", path)


def _adjustment_ids(
    diagram: CausalDiagram, action_ids: list[int], adjustment: Mapping[Node, Iterable[Node]]
) -> dict[int, set[int]]:
    names = diagram._nodes
    unknown = set(adjustment) - {names[x] for x in action_ids}
    if unknown:
        raise GraphError(f"adjustment sets given for nodes that are not actions: {sorted(map(repr, unknown))}")
    sets: dict[int, set[int]] = {}
    for x in action_ids:
        if names[x] not in adjustment:
            raise GraphError(f"no adjustment set given for action {names[x]!r}")
        z = {diagram._id(v) for v in adjustment[names[x]]}
        bad = [names[v] for v in z if v in diagram._latent or diagram._rank[v] >= diagram._rank[x]]
        if bad:
            raise GraphError(
                f"adjustment set of {names[x]!r} must hold observed nodes that precede it, got {bad}"
            )
        sets[x] = z
    return sets


def sequential_pi_backdoor(
    diagram: CausalDiagram,
    actions: Iterable[Node],
    reward: Node,
    adjustment: Mapping[Node, Iterable[Node]],
) -> BackdoorReport:
    """Check the sequential pi-backdoor criterion (Definition 2) for a family of sets.

    For every action ``X_t`` the manipulated graph ``G'_t`` removes all incoming edges of
    the later actions and gives each later ``X_j`` the parents ``Z_j``; the family passes
    when, for every ``t``, ``X_t`` is d-separated from ``reward`` given ``Z_t`` once its
    outgoing edges are removed, or ``X_t`` is not an ancestor of ``reward`` in ``G'_t``.

    Args:
        diagram: the causal diagram (latent nodes included).
        actions: the action nodes.
        reward: the outcome node.
        adjustment: action -> its set ``Z_t``: observed nodes that precede the action in the
            diagram's topological order (give the diagram an ``order`` to fix ties).

    Raises:
        GraphError: for an unknown or latent node, a missing set, or a set holding a
            latent node or one that does not precede its action.

    Examples:
        >>> g = CausalDiagram([("Z", "X"), ("Z", "Y"), ("X", "Y"), ("O", "X"), ("O", "W")],
        ...                   bidirected=[("W", "Y")], latent=["O"], nodes=["Z", "O", "W", "X", "Y"])
        >>> sequential_pi_backdoor(g, ["X"], "Y", {"X": {"Z"}}).holds
        True
        >>> sequential_pi_backdoor(g, ["X"], "Y", {"X": {"Z", "W"}}).witnesses
        {'X': ('X', 'O', 'W', 'Y')}
    """
    action_ids = _action_ids(diagram, actions)
    y = diagram._id(reward)
    sets = _adjustment_ids(diagram, action_ids, adjustment)
    names = diagram._nodes
    reasons: dict[Node, str] = {}
    witnesses: dict[Node, tuple[Node, ...]] = {}
    graph = _ManipulatedGraph(diagram)
    for x in reversed(action_ids):
        reason, path = graph.check(x, sets[x], y)
        reasons[names[x]] = reason
        if path is not None:
            witnesses[names[x]] = tuple(names[v] for v in path)
        graph.make_future(x, sets[x])
    reasons = {names[x]: reasons[names[x]] for x in action_ids}
    witnesses = {names[x]: witnesses[names[x]] for x in action_ids if names[x] in witnesses}
    return BackdoorReport(holds=not witnesses, reasons=reasons, witnesses=witnesses)


class _AncestralView:
    """``G^Y`` (the ancestors of the reward) seen through its latent projection onto the
    observed nodes, without building that projection.

    C-components of the projection come from a union-find over ``G^Y``: a latent node is
    merged with its children and every bidirected edge merges its ends. This is exact
    because in ``G^Y`` every latent node reaches an observed node (at worst the reward)
    through latent-only paths, and all of those are pairwise bidirected in the projection.
    """

    def __init__(self, diagram: CausalDiagram, reward: int) -> None:
        self.g = diagram
        self.reward = reward
        self.nodes = _ancestor_ids(diagram._pa, [reward])
        self.latent = diagram._latent
        root = {v: v for v in self.nodes}

        def find(v: int) -> int:
            while root[v] != v:
                root[v] = root[root[v]]
                v = root[v]
            return v

        for v in self.nodes:
            links = diagram._ch[v] if v in self.latent else ()
            for u in (*links, *diagram._sp[v]):
                if u in self.nodes:
                    a, b = find(u), find(v)
                    if a != b:
                        root[a] = b
        self.component: dict[int, int] = {}
        self.members: dict[int, list[int]] = {}
        for v in self.nodes:
            if v not in self.latent:
                r = find(v)
                self.component[v] = r
                self.members.setdefault(r, []).append(v)
        self._ch_plus: dict[int, list[int]] = {}
        self._pa_plus: dict[int, set[int]] = {}

    def ch_plus(self, v: int, stop: Mapping[int, object] | None = None) -> list[int] | None:
        """Children in the projection; with ``stop``, None as soon as one is not a key of it."""
        if v in self._ch_plus:
            found = self._ch_plus[v]
            return found if stop is None or all(c in stop for c in found) else None
        ch, latent, nodes = self.g._ch, self.latent, self.nodes
        found_set: set[int] = set()
        seen: set[int] = set()
        stack = [v]
        while stack:
            for c in ch[stack.pop()]:
                if c not in nodes:
                    continue
                if c in latent:
                    if c not in seen:
                        seen.add(c)
                        stack.append(c)
                elif stop is not None and c not in stop:
                    return None
                else:
                    found_set.add(c)
        found = sorted(found_set)
        self._ch_plus[v] = found
        return found

    def projected_parents(self, comp: int) -> set[int]:
        """Observed parents, in the projection, of the members of one C-component."""
        if comp not in self._pa_plus:
            pa, latent = self.g._pa, self.latent
            result: set[int] = set()
            seen: set[int] = set()
            stack = list(self.members[comp])
            while stack:
                for p in pa[stack.pop()]:
                    if p in latent:
                        if p not in seen:
                            seen.add(p)
                            stack.append(p)
                    else:
                        result.add(p)
            self._pa_plus[comp] = result
        return self._pa_plus[comp]


class _ComponentGraph:
    """``G_C`` of HasValidAdjustment for one C-component ``C``: the subgraph of ``G^Y`` on the
    ancestors of ``C`` once the projected parents ``pa(C)`` lose their incoming edges, i.e.
    ``Pa+(C)`` and the latent variables in between.

    The conditioning sets ``O^C ∩ before(X_i)`` are prefixes in temporal order, so instead
    of an ancestor search per query it keeps, for each node, the two earliest descendants
    (within ``G_C``) in ``O^C = C \\ O^X``: a node is an ancestor of the conditioning set
    iff one of them other than the queried ``O_i`` precedes ``X_i``. Rebuilt only when a
    member of ``C`` joins ``O^X``.
    """

    def __init__(self, view: _AncestralView, comp: int) -> None:
        g = view.g
        self.rank = g._rank
        self.members = view.members[comp]
        pa_c = view.projected_parents(comp)
        self.nodes = set(self.members)
        stack = [m for m in self.members if m not in pa_c]
        while stack:
            for p in g._pa[stack.pop()]:
                if p not in self.nodes:
                    self.nodes.add(p)
                    if p not in pa_c:
                        stack.append(p)
        self.nodes |= pa_c
        self.order = sorted(self.nodes, key=self.rank.__getitem__, reverse=True)
        self.children = {v: [c for c in g._ch[v] if c in self.nodes] for v in self.nodes}
        self.open_members: frozenset[int] | None = None
        self.earliest: dict[int, tuple[tuple[int, int], ...]] = {}

    def refresh(self, keys: Mapping[int, object]) -> None:
        open_members = frozenset(m for m in self.members if m not in keys)
        if open_members == self.open_members:
            return
        self.open_members = open_members
        rank, children = self.rank, self.children
        earliest: dict[int, tuple[tuple[int, int], ...]] = {}
        for v in self.order:
            best = {(rank[v], v)} if v in open_members else set()
            for c in children[v]:
                best.update(earliest[c])
            earliest[v] = tuple(sorted(best)[:2])
        self.earliest = earliest

    def separated(self, g: CausalDiagram, source: int, before_rank: int) -> bool:
        """``O_i ⊥ O^C | O^C ∩ before(X_i)`` in ``G_C``."""
        open_members, rank, earliest = self.open_members, g._rank, self.earliest
        assert open_members is not None
        if not any(m != source and rank[m] >= before_rank for m in open_members):
            return True

        def conditioned(v: int) -> bool:
            return v in open_members and v != source and rank[v] < before_rank

        def target(v: int) -> bool:
            return v in open_members and v != source and rank[v] >= before_rank

        def collider_open(v: int) -> bool:
            return any(node != source and r < before_rank for r, node in earliest[v])

        path = _find_open_path(g._pa, g._ch, g._sp, [source], conditioned, collider_open, target, self.nodes.__contains__)
        return path is None


def _find_ox_map(diagram: CausalDiagram, actions: Iterable[Node], reward: Node) -> tuple[dict[int, int], _AncestralView]:
    action_ids = set(_action_ids(diagram, actions))
    view = _AncestralView(diagram, diagram._id(reward))
    rank = diagram._rank
    candidates = sorted(
        (v for v in view.component if v != view.reward), key=rank.__getitem__, reverse=True
    )
    graphs: dict[int, _ComponentGraph] = {}

    def has_valid_adjustment(keys: Mapping[int, int], oi: int, xi: int) -> bool:
        comp = view.component[oi]
        if comp not in graphs:
            graphs[comp] = _ComponentGraph(view, comp)
        gc = graphs[comp]
        gc.refresh(keys)
        return gc.separated(diagram, oi, rank[xi])

    ox: dict[int, int] = {}
    while True:
        previous = dict(ox)
        for oi in candidates:
            children = view.ch_plus(oi, stop=ox)
            if children:
                xi = min((ox[c] for c in children), key=rank.__getitem__)
                if has_valid_adjustment(ox, oi, xi):
                    ox[oi] = xi
            elif oi in action_ids and has_valid_adjustment(ox, oi, oi):
                ox[oi] = oi
        if ox == previous:
            return ox, view


def find_ox(diagram: CausalDiagram, actions: Iterable[Node], reward: Node) -> frozenset[Node]:
    """Kumor et al.'s FindOX: the largest set ``O^X`` of observed ancestors of ``reward`` from
    which sequential pi-backdoor sets can be built (a family exists iff every action that is
    an ancestor of the reward belongs to it).

    Faithful to the appendix's pseudocode (and to the reference implementation's reading of
    it): observed nodes of ``G^Y`` are visited in reverse temporal order, repeatedly, until
    the map ``O^X -> X`` stops changing; ``ch+`` and the C-components are those of the
    latent projection of ``G^Y``; HasValidAdjustment tests
    ``O_i ⊥ O^C | O^C ∩ before(X_i)`` in ``G_C``, the subgraph of ``G^Y`` on ``Pa+(C)`` and
    the latent variables in between, with ``O^C = C \\ (O^X ∪ {O_i})``.

    Examples:
        >>> g = CausalDiagram([("Z", "X"), ("Z", "Y"), ("X", "Y"), ("O", "X"), ("O", "W")],
        ...                   bidirected=[("W", "Y")], latent=["O"], nodes=["Z", "O", "W", "X", "Y"])
        >>> sorted(find_ox(g, ["X"], "Y"))
        ['X']
    """
    ox, _ = _find_ox_map(diagram, actions, reward)
    return frozenset(diagram._nodes[v] for v in ox)

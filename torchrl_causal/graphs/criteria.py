"""The sequential pi-backdoor criterion (Definition 2) and Kumor et al.'s FindOX.

Everything here runs on the integer adjacency of a :class:`CausalDiagram` (its
:attr:`~CausalDiagram.indexed` view) and never materialises a latent projection: on
unrolled diagrams with a persistent hidden variable the projection has a quadratic number
of bidirected edges, whereas the searches below stay linear per query.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol, cast

from .diagram import CausalDiagram
from .errors import GraphError, NotImitableError
from .indexed import UnionFind, find_open_path, reach

Node = Hashable

__all__ = [
    "BackdoorReport",
    "ExactAdjustment",
    "SetRule",
    "find_adjustment",
    "find_ox",
    "sequential_pi_backdoor",
    "sequential_pi_backdoor_by_rule",
]


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


def _temporal(diagram: CausalDiagram, actions: Node | Iterable[Node], reward: Node) -> tuple[CausalDiagram, list[int], int]:
    """The diagram with the temporal order that Definition 2 is read in, the actions in that
    order, and the reward.

    A diagram built with an ``order`` keeps it. Without one, the actions take the order in
    which they are listed (a set of actions takes the default topological order) and every
    other node goes as early as its ancestry allows: before ``X_t`` lies everything that is
    not a descendant of ``X_t`` or of a later action. An adjustment set may then hold any
    observed non-descendant of its action (the backdoor rule), except descendants of later
    actions, which would close a cycle through the time order of the actions.
    """
    g = diagram.indexed
    y = g.id(reward)
    single = actions in diagram
    # One node of the diagram, or else the iterable of them that the signature allows.
    listed = [g.id(cast(Node, actions))] if single else [g.id(v) for v in cast(Iterable[Node], actions)]
    names = g.nodes
    if len(set(listed)) != len(listed):
        twice = next(names[v] for v in listed if listed.count(v) > 1)
        raise GraphError(f"action {twice!r} is listed twice")
    if y in listed:
        raise GraphError(f"the reward {reward!r} cannot also be an action")
    hidden = [names[i] for i in listed if i in g.latent]
    if hidden:
        raise GraphError(f"actions must be observed nodes, got latent {hidden}")
    if diagram.has_explicit_order:
        return diagram, sorted(listed, key=g.rank.__getitem__), y
    if not isinstance(actions, Sequence) or isinstance(actions, str):
        listed.sort(key=g.rank.__getitem__)
    # level[v] = the latest action t with v a descendant of X_t (0 when none): the nested
    # sets D_t = De(X_t) ∪ D_{t+1} are reached latest action first, each node once.
    level = [0] * len(names)
    for t in range(len(listed), 0, -1):
        x = listed[t - 1]
        if level[x]:
            later = next(names[a] for a in listed[t:] if x in reach(g.children, [a]))
            raise GraphError(
                f"actions must be listed in temporal order, but {later!r} (listed after {names[x]!r}) is "
                f"an ancestor of it; reorder them, or build the CausalDiagram with order=[...]"
            )
        level[x] = t
        for c in reach(g.children, [x], within=lambda v: not level[v]):
            level[c] = t
    first = {x: t for t, x in enumerate(listed, 1)}
    rank = g.rank
    order = sorted(range(len(names)), key=lambda v: (level[v], first.get(v) != level[v], rank[v]))
    ordered = diagram.with_order([names[v] for v in order])
    return ordered, listed, y


class _ManipulatedGraph:
    """``G'_t`` of a family, built incrementally, latest action first.

    Going backwards in time, each action in turn becomes a "future" action: it loses every
    incoming edge (directed and bidirected: under ``do(pi)`` it responds to its adjustment
    set alone) and gets its set as parents. Each step costs the degree of one action, so
    checking all ``H`` actions costs ``H`` searches and no graph copies.

    Whether ``X_t`` causes the reward in ``G'_t`` is read off a single graph, the one where
    every action responds to its set: the two differ only in edges into actions up to
    ``X_t``, which no directed path out of ``X_t`` can use (the sets precede their
    actions). One ancestor search thus serves every action.
    """

    def __init__(self, diagram: CausalDiagram, sets: Mapping[int, set[int]], reward: int) -> None:
        g = diagram.indexed
        self.rank = g.rank
        self.sets = sets
        self.pa = [list(p) for p in g.parents]
        self.ch = [list(c) for c in g.children]
        self.sp = [list(s) for s in g.siblings]
        policy_parents = [sets[v] if v in sets else p for v, p in enumerate(g.parents)]
        self.causes_reward = {reward} | reach(policy_parents, [reward])

    def make_future(self, action: int) -> None:
        pa, ch, sp = self.pa, self.ch, self.sp
        for p in pa[action]:
            ch[p].remove(action)
        for s in sp[action]:
            sp[s].remove(action)
        pa[action] = list(self.sets[action])
        sp[action] = []
        for z in pa[action]:
            ch[z].append(action)

    def _ancestor_test(self, x: int, z: set[int]) -> Callable[[int], bool]:
        """``v ∈ An(z)``, searched lazily: open colliders are few, and ``An(z)`` of a window
        reaches back to the start of the episode. A directed path into ``z`` only visits
        nodes before ``x``, where ``G'_t`` is the original graph."""
        return _ancestor_test(self.rank, self.ch, x, z.__contains__)

    def check(self, x: int, reward: int) -> tuple[str, list[int] | None]:
        """Definition 2 for ``x`` (every later action already made future)."""
        if x not in self.causes_reward:
            return "not_ancestor", None
        z = self.sets[x]
        path = find_open_path(self.pa, self.ch, self.sp, [x], z.__contains__, self._ancestor_test(x, z), reward.__eq__, cut=x)
        return ("separated", None) if path is None else ("open_path", path)


def _ancestor_test(rank: Sequence[int], ch: Sequence[Sequence[int]], x: int, in_z: Callable[[int], bool]) -> Callable[[int], bool]:
    """``v ∈ An(Z)`` through nodes before ``x`` (``Z`` precedes ``x``), searched lazily and
    remembered for one check."""
    limit = rank[x]
    known: dict[int, bool] = {}

    def test(v: int) -> bool:
        if in_z(v):
            return True
        if rank[v] >= limit:
            return False
        if v in known:
            return known[v]
        seen = {v}
        stack = [v]
        while stack:
            for c in ch[stack.pop()]:
                if in_z(c) or known.get(c):
                    known[v] = True
                    return True
                if c not in seen and rank[c] < limit and c not in known:
                    seen.add(c)
                    stack.append(c)
        known.update(dict.fromkeys(seen, False))
        return False

    return test


class SetRule(Protocol):
    """A family of adjustment sets given by a rule instead of a list, on one diagram's ids.

    A window conditions every step on the same lags, so its family lists ``O(H k)`` nodes
    over ``H`` actions although the rule that makes it is ``O(k)``: checking Definition 2
    through the rule (:func:`sequential_pi_backdoor_by_rule`) costs what the searches
    visit, not what the family lists.
    """

    def holds(self, action: int, node: int) -> bool:
        """Whether ``node`` is in the set of ``action``."""
        ...

    def members(self, action: int) -> list[int]:
        """The set of ``action`` in the order :func:`sequential_pi_backdoor` would list it
        (the iteration order of the ``set`` of ids it builds from the named set)."""
        ...

    def holders(self, node: int, after: int) -> list[int]:
        """The actions later than the action ``after`` whose set holds ``node``, latest first."""
        ...

    def policy_ancestors(self, reward: int) -> set[int]:
        """``reward`` and its ancestors once every action responds to its set alone."""
        ...


class _RuleManipulatedGraph:
    """:class:`_ManipulatedGraph` of a family given by a :class:`SetRule`: its adjacency
    lists are computed when the search asks for them, each equal, element for element and
    in order, to the list :class:`_ManipulatedGraph` would hold at that check. So the
    searches, and the paths they return, are the same, without the ``O(H k)`` set edges.

    In :class:`_ManipulatedGraph` at the check of ``X_t`` the later actions have been made
    future, latest first: a node's children are its original children less the future
    actions, then the future actions whose set holds it, latest first (appended in that
    order); a future action's parents are its set and it has no siblings; every other
    sibling list loses the future actions.
    """

    def __init__(self, diagram: CausalDiagram, rule: SetRule, action_ids: Sequence[int], reward: int) -> None:
        g = diagram.indexed
        self.g = g
        self.rule = rule
        self.rank = g.rank
        self.actions = frozenset(action_ids)
        self.boundary = len(g.nodes)  # rank of the earliest future action (none yet)
        self.current = -1  # the action being checked
        self.causes_reward = rule.policy_ancestors(reward)
        self._members: dict[int, list[int]] = {}
        self.pa = _LazyLists(self._parents)
        self.ch = _LazyLists(self._children)
        self.sp = _LazyLists(self._siblings)
        self.original_ch = g.children

    def _future(self, v: int) -> bool:
        return v in self.actions and self.rank[v] >= self.boundary

    def _parents(self, v: int) -> Sequence[int]:
        if self._future(v):
            if v not in self._members:
                self._members[v] = self.rule.members(v)
            return self._members[v]
        return self.g.parents[v]

    def _children(self, v: int) -> list[int]:
        kept = [c for c in self.g.children[v] if not self._future(c)]
        return kept + self.rule.holders(v, self.current)

    def _siblings(self, v: int) -> Sequence[int]:
        if self._future(v):
            return ()
        return [s for s in self.g.siblings[v] if not self._future(s)]

    def make_future(self, action: int) -> None:
        self.boundary = self.rank[action]

    def check(self, x: int, reward: int) -> tuple[str, list[int] | None]:
        self.current = x
        if x not in self.causes_reward:
            return "not_ancestor", None

        def in_z(v: int) -> bool:
            return self.rule.holds(x, v)

        # An(Z) only walks nodes before x, whose children in G'_t are the original ones
        # (the set edges all point into later actions).
        collider_open = _ancestor_test(self.rank, self.original_ch, x, in_z)
        path = find_open_path(self.pa, self.ch, self.sp, [x], in_z, collider_open, reward.__eq__, cut=x)
        return ("separated", None) if path is None else ("open_path", path)


class _LazyLists(Sequence[Sequence[int]]):
    """A read-only sequence whose item ``v`` is computed when asked for."""

    def __init__(self, item: Callable[[int], Sequence[int]]) -> None:
        self._item = item

    def __getitem__(self, v):  # type: ignore[override]
        return self._item(v)

    def __len__(self) -> int:  # pragma: no cover - the searches only index
        raise TypeError("a lazily computed adjacency has no length")


def _adjustment_ids(
    diagram: CausalDiagram, action_ids: list[int], adjustment: Mapping[Node, Iterable[Node]], given_order: bool
) -> dict[int, set[int]]:
    g = diagram.indexed
    names, rank, index = g.nodes, g.rank, g.index
    unknown = set(adjustment) - {names[x] for x in action_ids}
    if unknown:
        raise GraphError(f"adjustment sets given for nodes that are not actions: {sorted(map(repr, unknown))}")
    sets: dict[int, set[int]] = {}
    for x in action_ids:
        if names[x] not in adjustment:
            raise GraphError(f"no adjustment set given for action {names[x]!r}")
        given = adjustment[names[x]]
        if isinstance(given, str) or not isinstance(given, Iterable):
            raise GraphError(
                f"the adjustment set of {names[x]!r} must be a collection of nodes, got {given!r}; write a single node as {{{given!r}}}"
            )
        try:
            z = set(map(index.__getitem__, given))
        except (KeyError, TypeError):
            z = {g.id(v) for v in given}  # names the unknown node
        if not z:
            sets[x] = z
            continue
        if not z.isdisjoint(g.latent):
            raise GraphError(f"the adjustment set of {names[x]!r} holds latent nodes {[names[v] for v in z & g.latent]}")
        if max(map(rank.__getitem__, z)) >= rank[x]:
            late = [names[v] for v in sorted((v for v in z if rank[v] >= rank[x]), key=rank.__getitem__)]
            if given_order:
                raise GraphError(f"the adjustment set of {names[x]!r} must precede it in the diagram's order, got {late}")
            raise GraphError(
                f"the adjustment set of {names[x]!r} holds {late}, descendants of {names[x]!r} or of a later "
                "action: conditioning on them would need a cycle in the manipulated graph (give the "
                "CausalDiagram an explicit order=[...] if the actions or nodes come in another temporal order)"
            )
        sets[x] = z
    return sets


def sequential_pi_backdoor(
    diagram: CausalDiagram,
    actions: Node | Iterable[Node],
    reward: Node,
    adjustment: Mapping[Node, Iterable[Node]],
    check: Iterable[Node] | None = None,
) -> BackdoorReport:
    """Check the sequential pi-backdoor criterion (Definition 2) for a family of sets.

    For every action ``X_t`` the manipulated graph ``G'_t`` removes all incoming edges of
    the later actions and gives each later ``X_j`` the parents ``Z_j``; the family passes
    when, for every ``t``, ``X_t`` is d-separated from ``reward`` given ``Z_t`` once its
    outgoing edges are removed, or ``X_t`` is not an ancestor of ``reward`` in ``G'_t``.

    Args:
        diagram: the causal diagram (latent nodes included).
        actions: the action nodes in temporal order. A diagram built with an ``order``
            sorts them by it; otherwise they keep the order given (a set of actions takes
            the default topological order).
        reward: the outcome node (not one of the actions).
        adjustment: action -> its set ``Z_t``, a collection of observed nodes. With an
            ``order``, the nodes that precede the action in it; without one, any observed
            node that is no descendant of the action or of a later action (the standard
            backdoor rule, with the actions in time order).
        check: only check these actions (every set still shapes the manipulated graphs);
            ``reasons`` and ``holds`` then cover them alone. Default: every action.

    Raises:
        GraphError: for an unknown or latent node, the reward among the actions, actions
            listed against their ancestry, a missing set, a set given as a string, or a set
            holding a latent node or one that cannot precede its action.

    Examples:
        >>> g = CausalDiagram([("Z", "X"), ("Z", "Y"), ("X", "Y"), ("O", "X"), ("O", "W")],
        ...                   bidirected=[("W", "Y")], latent=["O"], nodes=["Z", "O", "W", "X", "Y"])
        >>> sequential_pi_backdoor(g, ["X"], "Y", {"X": {"Z"}}).holds
        True
        >>> sequential_pi_backdoor(g, ["X"], "Y", {"X": {"Z", "W"}}).witnesses
        {'X': ('X', 'O', 'W', 'Y')}
    """
    g, action_ids, y = _temporal(diagram, actions, reward)
    sets = _adjustment_ids(g, action_ids, adjustment, diagram.has_explicit_order)
    checked = _checked(g, action_ids, check)
    return _report(_ManipulatedGraph(g, sets, y), g, action_ids, checked, y)


def _checked(g: CausalDiagram, action_ids: list[int], check: Iterable[Node] | None) -> set[int]:
    names = g.indexed.nodes
    checked = set(action_ids) if check is None else {g.indexed.id(v) for v in check}
    if not checked <= set(action_ids):
        raise GraphError(f"check names nodes that are not actions: {sorted(repr(names[v]) for v in checked - set(action_ids))}")
    return checked


def _report(
    graph: _ManipulatedGraph | _RuleManipulatedGraph, g: CausalDiagram, action_ids: list[int], checked: set[int], y: int
) -> BackdoorReport:
    names = g.indexed.nodes
    reasons: dict[Node, str] = {}
    witnesses: dict[Node, tuple[Node, ...]] = {}
    for x in reversed(action_ids):
        if x in checked:
            reason, path = graph.check(x, y)
            reasons[names[x]] = reason
            if path is not None:
                witnesses[names[x]] = tuple(names[v] for v in path)
        graph.make_future(x)
    reasons = {names[x]: reasons[names[x]] for x in action_ids if x in checked}
    witnesses = {names[x]: witnesses[names[x]] for x in action_ids if names[x] in witnesses}
    return BackdoorReport(holds=not witnesses, reasons=reasons, witnesses=witnesses)


def sequential_pi_backdoor_by_rule(
    diagram: CausalDiagram,
    actions: Iterable[Node],
    reward: Node,
    rule: SetRule,
    check: Iterable[Node] | None = None,
) -> BackdoorReport:
    """:func:`sequential_pi_backdoor` of the family that ``rule`` gives, without listing it.

    The report is the one :func:`sequential_pi_backdoor` gives for the listed family (the
    same reasons and the same witness paths): the manipulated graphs' adjacency is computed
    when the searches reach it, list for list as the listed check would hold it. The cost
    is what the searches visit. ``diagram`` must have an explicit order (an unrolled
    template has one), and ``rule`` must give observed sets that precede their actions; it
    is not checked node by node (that would list the family).

    Raises:
        GraphError: a diagram without an explicit order, or the errors of
            :func:`sequential_pi_backdoor` about the actions, the reward and ``check``.
    """
    if not diagram.has_explicit_order:
        raise GraphError("sequential_pi_backdoor_by_rule needs a diagram with an explicit order (order=[...])")
    g, action_ids, y = _temporal(diagram, list(actions), reward)
    checked = _checked(g, action_ids, check)
    return _report(_RuleManipulatedGraph(g, rule, action_ids, y), g, action_ids, checked, y)


class _AncestralView:
    """``G^Y`` (the ancestors of the reward) seen through its latent projection onto the
    observed nodes, without building that projection.

    C-components of the projection come from a union-find over ``G^Y``: a latent node is
    merged with its children and every bidirected edge merges its ends. This is exact
    because in ``G^Y`` every latent node reaches an observed node (at worst the reward)
    through latent-only paths, and all of those are pairwise bidirected in the projection.
    """

    def __init__(self, diagram: CausalDiagram, reward: int) -> None:
        self.g = diagram.indexed
        self.reward = reward
        g = self.g
        self.nodes = {reward} | reach(g.parents, [reward])
        self.latent = g.latent
        components = UnionFind(self.nodes)
        for v in self.nodes:
            links = g.children[v] if v in self.latent else ()
            for u in (*links, *g.siblings[v]):
                if u in self.nodes:
                    components.union(u, v)
        self.component: dict[int, int] = {}
        self.members: dict[int, list[int]] = {}
        for v in self.nodes:
            if v not in self.latent:
                r = components.find(v)
                self.component[v] = r
                self.members.setdefault(r, []).append(v)
        self._ch_plus: dict[int, list[int]] = {}
        self._ancestry: dict[int, tuple[set[int], set[int]]] = {}

    def ch_plus(self, v: int, stop: Mapping[int, object] | None = None) -> list[int] | None:
        """Children in the projection; with ``stop``, None when one is not a key of it."""
        if v not in self._ch_plus:
            latent = self.latent
            reached = reach(self.g.children, [v], through=latent.__contains__, within=self.nodes.__contains__)
            self._ch_plus[v] = sorted(c for c in reached if c not in latent)
        found = self._ch_plus[v]
        return found if stop is None or all(c in stop for c in found) else None

    def latent_ancestry(self, comp: int) -> tuple[set[int], set[int]]:
        """The observed parents, in the projection, of the members of one C-component, and
        the latent nodes on the latent-only directed paths into them."""
        if comp not in self._ancestry:
            latent = self.latent
            reached = reach(self.g.parents, self.members[comp], through=latent.__contains__)
            self._ancestry[comp] = reached - latent, reached & latent
        return self._ancestry[comp]

    def projected_parents(self, comp: int) -> set[int]:
        """Observed parents, in the projection, of the members of one C-component."""
        return self.latent_ancestry(comp)[0]


class _ComponentGraph:
    """``G_C`` of HasValidAdjustment for one C-component ``C`` of the projection of ``G^Y``:
    the members of ``C``, their projected parents ``pa(C)`` and the intermediate latent
    variables (those on latent-only directed paths into a member, including paths into
    members that are themselves parents of other members). The parents outside ``C`` are
    held fixed, as in the c-factor ``Q[C]``: no incoming edges.

    The conditioning sets ``O^C ∩ before(X_i)`` are prefixes in temporal order, so instead
    of an ancestor search per query it keeps, for each node, the two earliest descendants
    (within ``G_C``) in ``O^C = C \\ O^X``: a node is an ancestor of the conditioning set
    iff one of them other than the queried ``O_i`` precedes ``X_i``. Rebuilt only when a
    member of ``C`` joins ``O^X``.
    """

    def __init__(self, view: _AncestralView, comp: int, actions: set[int], keys: Mapping[int, object]) -> None:
        g = view.g
        self.g = g
        self.actions = actions
        self.members = view.members[comp]
        parents, between = view.latent_ancestry(comp)
        self.held = parents.difference(self.members)
        self.nodes = set(self.members) | parents | between
        self.order = sorted(self.nodes, key=g.rank.__getitem__, reverse=True)
        self.children = {v: [c for c in g.children[v] if c in self.nodes and c not in self.held] for v in self.nodes}
        self.open_members = {m for m in self.members if m not in keys}
        self.earliest: dict[int, tuple[tuple[int, int], ...]] = {}
        self.latest: list[tuple[int, int]] = []  # the two latest open members, (rank, node)
        self.stale = True

    def leave(self, member: int) -> None:
        """``member`` joined ``O^X``."""
        if member in self.open_members:
            self.open_members.remove(member)
            self.stale = True

    def refresh(self) -> None:
        if not self.stale:
            return
        self.stale = False
        rank, children, open_members = self.g.rank, self.children, self.open_members
        earliest: dict[int, tuple[tuple[int, int], ...]] = {}
        for v in self.order:
            best = {(rank[v], v)} if v in open_members else set()
            for c in children[v]:
                best.update(earliest[c])
            earliest[v] = tuple(sorted(best)[:2])
        self.earliest = earliest
        self.latest = sorted(((rank[m], m) for m in open_members), reverse=True)[:2]

    def separated(self, source: int, action: int, keys: Mapping[int, object]) -> bool:
        """Whether ``O_i ⊥ O^C | O^C ∩ before(X_i)`` holds in ``G_C`` as ``G'_i`` changes it.

        ``G'_i`` is the graph that Definition 2 reads the adjustment of ``X_i`` in: the
        outgoing edges of ``X_i`` are removed, the later actions of ``O^X`` lose their
        incoming edges (without gaining edges from their sets), and the fixed parents
        that precede ``X_i`` are conditioned on (the sets of :func:`find_adjustment` take
        them from the Markov boundary). Each of the three is needed for agreement with
        the brute-force search of ``tests/test_graphs_bruteforce.py``.
        """
        self.refresh()
        g, held, actions = self.g, self.held, self.actions
        open_members, rank, earliest = self.open_members, g.rank, self.earliest
        before_rank = rank[action]
        if not any(m != source and r >= before_rank for r, m in self.latest):
            return True

        def conditioned(v: int) -> bool:
            return rank[v] < before_rank and (v in held or v in open_members and v != source)

        def target(v: int) -> bool:
            return v in open_members and v != source and rank[v] >= before_rank

        def collider_open(v: int) -> bool:
            return any(node != source and r < before_rank for r, node in earliest[v])

        def fixed(v: int) -> bool:
            return v in held or v in actions and v in keys and rank[v] > before_rank

        path = find_open_path(
            g.parents,
            g.children,
            g.siblings,
            [source],
            conditioned,
            collider_open,
            target,
            self.nodes.__contains__,
            cut=action,
            fixed=fixed,
        )
        return path is None


def _find_ox_map(g: CausalDiagram, action_ids: list[int], y: int) -> tuple[dict[int, int], _AncestralView]:
    actions = set(action_ids)
    view = _AncestralView(g, y)
    rank = g.indexed.rank
    candidates = sorted((v for v in view.component if v != y), key=rank.__getitem__, reverse=True)
    graphs: dict[int, _ComponentGraph] = {}

    ox: dict[int, int] = {}

    def has_valid_adjustment(oi: int, xi: int) -> bool:
        comp = view.component[oi]
        if comp not in graphs:
            graphs[comp] = _ComponentGraph(view, comp, actions, ox)
        return graphs[comp].separated(oi, xi, ox)

    def join(oi: int, xi: int) -> None:
        if oi not in ox and view.component[oi] in graphs:
            graphs[view.component[oi]].leave(oi)
        ox[oi] = xi

    while True:
        previous = dict(ox)
        for oi in candidates:
            children = view.ch_plus(oi, stop=ox)
            if children:
                xi = min((ox[c] for c in children), key=rank.__getitem__)
                if has_valid_adjustment(oi, xi):
                    join(oi, xi)
            elif oi in actions and has_valid_adjustment(oi, oi):
                join(oi, oi)
        if ox == previous:
            return ox, view


def find_ox(diagram: CausalDiagram, actions: Node | Iterable[Node], reward: Node) -> frozenset[Node]:
    """Kumor et al.'s FindOX: the largest set ``O^X`` of observed ancestors of ``reward`` from
    which sequential pi-backdoor sets can be built (a family exists iff every action that is
    an ancestor of the reward belongs to it).

    Observed nodes of ``G^Y`` are visited in reverse temporal order, repeatedly, until the
    map ``O^X -> X`` stops changing; ``ch+`` and the C-components are those of the latent
    projection of ``G^Y``; HasValidAdjustment tests ``O_i ⊥ O^C | O^C ∩ before(X_i)``,
    ``O^C = C \\ (O^X ∪ {O_i})``, in ``G_C``: ``Pa+(C)`` and the intermediate latent
    variables. Where the appendix's pseudocode is terse, ``G_C`` is read as the graph that
    Definition 2 checks ``X_i`` in: it keeps the latent variables on every latent-only path
    into a member of ``C`` (also into members that are parents of other members), holds
    the parents outside ``C`` fixed and conditions on those before ``X_i``, removes the
    outgoing edges of ``X_i`` and the incoming edges of the later actions already in
    ``O^X``. That reading, unlike the literal one, agrees with a brute-force search over
    every family on tens of thousands of random small diagrams
    (``tests/test_graphs_bruteforce.py``).

    Args:
        diagram: the causal diagram (latent nodes included).
        actions: the action nodes, in temporal order (see :func:`sequential_pi_backdoor`).
        reward: the outcome node.

    Examples:
        >>> g = CausalDiagram([("Z", "X"), ("Z", "Y"), ("X", "Y"), ("O", "X"), ("O", "W")],
        ...                   bidirected=[("W", "Y")], latent=["O"], nodes=["Z", "O", "W", "X", "Y"])
        >>> sorted(find_ox(g, ["X"], "Y"))
        ['X']
    """
    g, action_ids, y = _temporal(diagram, actions, reward)
    ox, _ = _find_ox_map(g, action_ids, y)
    return frozenset(g.indexed.nodes[v] for v in ox)


def _certificate(g: CausalDiagram, action_ids: list[int], x: int, y: int) -> tuple[list[int], set[int]] | None:
    """Proof that action ``x`` fails Definition 2 in every family, or None.

    Emptying a later action's set only removes edges into it, which never makes the check
    of ``x`` harder, so the graph ``G°`` where the later actions keep no incoming edge at
    all is the most favourable ``G'_x``. When ``x`` causes ``y`` there and the set
    ``Z* = An({x, y}) ∩ O ∩ before(x)`` leaves a path open, no admissible set separates
    them (van der Zander et al., 2019: when any set between ``∅`` and ``R`` separates two
    nodes, ``An`` of the pair intersected with ``R`` does), hence no family passes at
    ``x``. Returns that open path and ``Z*``.
    """
    indexed = g.indexed
    rank, latent = indexed.rank, indexed.latent
    later = {a for a in action_ids if rank[a] > rank[x]}
    if y not in reach(indexed.children, [x], within=lambda c: c not in later):
        return None
    favourable_parents = [() if v in later else p for v, p in enumerate(indexed.parents)]
    conditioned = {v for v in {x, y} | reach(favourable_parents, [x, y]) if v not in latent and rank[v] < rank[x]}
    path = find_open_path(
        indexed.parents,
        indexed.children,
        indexed.siblings,
        [x],
        conditioned.__contains__,
        (conditioned | reach(favourable_parents, conditioned)).__contains__,
        y.__eq__,
        cut=x,
        fixed=later.__contains__,
    )
    return None if path is None else (path, conditioned)


@dataclass(frozen=True)
class ExactAdjustment:
    """The sequential pi-backdoor sets of one diagram, as Kumor et al. construct them.

    ``Z_t = (MB ∪ BA) ∩ before(X_t)`` for a boundary action and ``∅`` otherwise
    (Algorithm 1, lines 4-10). The sets are prefixes of one temporally sorted tuple,
    :attr:`conditioning_order`, so they are produced on demand instead of being stored
    (they grow linearly with ``t``).

    Attributes:
        diagram: the diagram the sets are for, with the temporal order they are read in.
        actions: the action nodes in temporal order.
        ox: FindOX's ``O^X``.
        markov_boundary: ``MB = Pa+(C(Ch+(O^X))) \\ O^X`` in the projection of ``G^Y_{X'}``.
        boundary_actions: actions in ``O^X`` with an effective child outside ``O^X``.
    """

    diagram: CausalDiagram
    actions: tuple[Node, ...]
    ox: frozenset[Node]
    markov_boundary: frozenset[Node]
    boundary_actions: frozenset[Node]

    @cached_property
    def conditioning_order(self) -> tuple[Node, ...]:
        """``MB ∪ BA`` in temporal order: ``Z_t`` of a boundary action is its prefix before ``X_t``."""
        g = self.diagram.indexed
        return g.in_order(g.id(v) for v in self.markov_boundary | self.boundary_actions)

    @cached_property
    def _conditioning_ranks(self) -> list[int]:
        g = self.diagram.indexed
        return [g.rank[g.id(v)] for v in self.conditioning_order]

    def set_size(self, action: Node) -> int:
        """``|Z_t|`` of ``action``: the length of its prefix of :attr:`conditioning_order`."""
        if action not in self.boundary_actions:
            if action not in self.actions:
                raise GraphError(f"{action!r} is not an action of this diagram")
            return 0
        g = self.diagram.indexed
        return bisect_left(self._conditioning_ranks, g.rank[g.id(action)])

    def adjustment_set(self, action: Node) -> frozenset[Node]:
        return frozenset(self.conditioning_order[: self.set_size(action)])

    @property
    def family(self) -> dict[Node, frozenset[Node]]:
        """Every action's set (materialised; quadratic in the horizon)."""
        return {x: self.adjustment_set(x) for x in self.actions}


def _not_imitable(g: CausalDiagram, action_ids: list[int], failing: list[int], y: int) -> NotImitableError:
    names = g.indexed.nodes
    shown = ", ".join(repr(names[x]) for x in failing[:6]) + (f" and {len(failing) - 6} more" if len(failing) > 6 else "")
    tried = failing[-8:]  # the latest ones have the fewest later actions to route around
    for x in reversed(tried):
        found = _certificate(g, action_ids, x, y)
        if found is not None:
            path, conditioned = found
            certificate = tuple(names[v] for v in path)
            return NotImitableError(
                f"no sequential pi-backdoor adjustment exists: FindOX leaves out {shown}. Certificate for "
                f"{names[x]!r}: even with every later action's set empty, it causes {names[y]!r} and "
                f"{' ~ '.join(map(repr, certificate))} stays open given the {len(conditioned)} observed ancestors "
                f"of {names[x]!r} and {names[y]!r} before it; when those do not separate the two, no set does",
                actions=[names[v] for v in failing],
                witness=certificate,
            )
    alone = "each of them" if len(tried) == len(failing) else f"each of the latest {len(tried)}"
    return NotImitableError(
        f"no sequential pi-backdoor adjustment exists: FindOX leaves out {shown}. No single action "
        f"certifies it: {alone} could meet Definition 2 if the later actions' sets were empty, but no family "
        "of sets meets it for all actions at once",
        actions=[names[v] for v in failing],
    )


def find_adjustment(diagram: CausalDiagram, actions: Node | Iterable[Node], reward: Node) -> ExactAdjustment:
    """Sequential pi-backdoor sets for every action, or a refusal: FindOX, the imitability
    test, the Markov boundary and the boundary actions (Algorithm 1, lines 2-10).

    Raises:
        NotImitableError: when some action that causes the reward is left out of ``O^X``
            (then no family meets Definition 2). It names those actions and, where one
            exists, carries a certificate path: open for one of them under every family.

    Examples:
        >>> g = CausalDiagram([("Z", "X"), ("Z", "Y"), ("X", "Y"), ("O", "X"), ("O", "W")],
        ...                   bidirected=[("W", "Y")], latent=["O"], nodes=["Z", "O", "W", "X", "Y"])
        >>> sorted(find_adjustment(g, ["X"], "Y").adjustment_set("X"))
        ['Z']
        >>> confounded = CausalDiagram([("L", "X"), ("L", "Y"), ("X", "Y")], latent=["L"])
        >>> try:
        ...     find_adjustment(confounded, ["X"], "Y")
        ... except NotImitableError as err:
        ...     err.witness
        ('X', 'L', 'Y')
    """
    g, action_ids, y = _temporal(diagram, actions, reward)
    ox_map, view = _find_ox_map(g, action_ids, y)
    failing = [x for x in action_ids if x in view.nodes and x not in ox_map]
    if failing:
        raise _not_imitable(g, action_ids, failing, y)
    ox = set(ox_map)
    acting = {x for x in action_ids if x in ox}
    # Ch(O^X) in the projection of G^Y with the outgoing edges of X' = O^X ∩ X removed.
    reached = set(ox)
    for v in ox - acting:
        reached.update(view.ch_plus(v) or ())
    boundary: set[int] = set()
    for comp in {view.component[v] for v in reached}:
        boundary.update(view.members[comp])
        boundary.update(view.projected_parents(comp))
    # Removing the edges out of X' only removes projected parents in X' ⊆ O^X, which MB
    # excludes anyway; it matters through Ch(O^X), which skips the children of X'.
    boundary -= ox
    boundary_actions = {x for x in acting if not set(view.ch_plus(x) or ()) <= ox}
    names = g.indexed.nodes
    return ExactAdjustment(
        diagram=g,
        actions=tuple(names[x] for x in action_ids),
        ox=frozenset(names[v] for v in ox),
        markov_boundary=frozenset(names[v] for v in boundary),
        boundary_actions=frozenset(names[v] for v in boundary_actions),
    )

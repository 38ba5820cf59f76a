"""Causal diagrams with directed and bidirected edges (semi-Markovian DAGs).

Nodes are arbitrary hashables. Internally every node is an int (its insertion index) and
adjacency is stored as tuples of ints, because the unrolled diagrams of long episodes
have tens of thousands of nodes and every search below must stay linear in their size.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Callable, Hashable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from .errors import GraphError

Node = Hashable

__all__ = ["CausalDiagram", "Confounder"]


@dataclass(frozen=True)
class Confounder:
    """The explicit latent common cause that :meth:`CausalDiagram.to_networkx` puts in place
    of a bidirected edge ``a <-> b``."""

    a: Node
    b: Node


def _ancestor_ids(parents: Sequence[Sequence[int]], seeds: Iterable[int]) -> set[int]:
    """The seeds and every node with a directed path into one of them."""
    found = set(seeds)
    stack = list(found)
    while stack:
        for p in parents[stack.pop()]:
            if p not in found:
                found.add(p)
                stack.append(p)
    return found


def _simple_path(walk: list[int]) -> list[int]:
    """Shortcut an open walk into an open path.

    Cutting the loop between the first and the last visit of a repeated node keeps the
    walk open: a node entered through a tail, or lying in An(Z), is fine at any junction;
    a conditioned node was entered and left through arrowheads (so stays a collider in
    An(Z)); and a node outside An(Z) entered through an arrowhead is left through a tail,
    after which the walk can only run down a directed path (any later collider would put
    the node in An(Z)), so it is never revisited.
    """
    while True:
        first: dict[int, int] = {}
        for i, v in enumerate(walk):
            if v in first:
                last = len(walk) - 1 - walk[::-1].index(v)
                walk = walk[: first[v]] + walk[last:]
                break
            first[v] = i
        else:
            return walk


def _find_open_path(
    parents: Sequence[Sequence[int]],
    children: Sequence[Sequence[int]],
    spouses: Sequence[Sequence[int]],
    sources: Iterable[int],
    blocked: Callable[[int], bool],
    collider_open: Callable[[int], bool],
    is_target: Callable[[int], bool],
    inside: Callable[[int], bool] | None = None,
    cut: int = -1,
    fixed: Callable[[int], bool] | None = None,
) -> list[int] | None:
    """Breadth-first Bayes-ball on a mixed graph; the shortest open path to a target, or None.

    A state is ``2 * node + head``: ``head`` is 1 when the walk entered ``node`` through an
    arrowhead (from a parent or a spouse) and 0 when it entered through a tail (from a
    child). Each state is expanded at most once, so the search is O(V + E). ``blocked`` is
    the conditioning set, ``collider_open`` its ancestral closure (colliders pass only
    there), ``inside`` restricts the search to an induced subgraph. Edges can be deleted
    without copying the graph: ``cut`` is a node whose outgoing edges are absent, ``fixed``
    marks the nodes whose incoming edges (directed and bidirected) are absent.
    """
    prev: dict[int, int] = {}
    queue: deque[int] = deque()
    for s in sources:
        if 2 * s not in prev:
            prev[2 * s] = -1
            queue.append(2 * s)
    while queue:
        state = queue.popleft()
        v = state >> 1
        origin = prev[state] == -1
        if not origin and is_target(v):
            walk = []
            while state != -1:
                walk.append(state >> 1)
                state = prev[state]
            return _simple_path(walk[::-1])
        down = () if v == cut else children[v]
        moves: list[int] = []
        if state & 1:
            if collider_open(v):
                moves.extend(2 * p for p in parents[v] if p != cut)
                moves.extend(2 * s + 1 for s in spouses[v])
            if not blocked(v):
                moves.extend(2 * c + 1 for c in down)
        elif origin or not blocked(v):
            moves.extend(2 * c + 1 for c in down)
            if fixed is None or not fixed(v):
                moves.extend(2 * p for p in parents[v] if p != cut)
                moves.extend(2 * s + 1 for s in spouses[v])
        for nxt in moves:
            if nxt in prev or (inside is not None and not inside(nxt >> 1)):
                continue
            if nxt & 1 and fixed is not None and fixed(nxt >> 1):
                continue
            prev[nxt] = state
            queue.append(nxt)
    return None


class CausalDiagram:
    """A causal diagram: a DAG of directed edges plus bidirected edges (latent confounding).

    Args:
        directed: pairs ``(a, b)`` meaning ``a -> b``.
        bidirected: pairs ``(a, b)`` meaning ``a <-> b`` (an unobserved common cause).
        latent: nodes unobserved by the imitator (they stay in the graph; see
            :meth:`latent_projection` to remove them).
        nodes: extra, possibly isolated, nodes.
        order: an explicit topological order of all nodes, used for "before" and for the
            extended parents; defaults to a topological sort that breaks ties by insertion.
            Without it, the sequential criteria read "before an action" as "not a
            descendant of it or of a later action" (see
            :func:`~torchrl_causal.graphs.sequential_pi_backdoor`).

    Raises:
        GraphError: on a self-loop, a directed cycle (named), a latent node that is not in
            the graph, or an ``order`` that is not a topological order of the nodes.

    Examples:
        >>> g = CausalDiagram([("Z", "X"), ("Z", "Y"), ("X", "Y"), ("O", "X"), ("O", "W")],
        ...                   bidirected=[("W", "Y")], latent=["O"], nodes=["Z", "O", "W", "X", "Y"])
        >>> g.is_d_separated({"X"}, {"Y"}, {"Z"})
        False
        >>> sorted(g.latent_projection(["Z", "X", "W", "Y"]).bidirected_edges)
        [('W', 'X'), ('W', 'Y')]
        >>> g.d_connecting_path({"O"}, {"Y"}, {"Z", "X", "W"})
        ('O', 'W', 'Y')
    """

    def __init__(
        self,
        directed: Iterable[tuple[Node, Node]],
        bidirected: Iterable[tuple[Node, Node]] = (),
        latent: Iterable[Node] = (),
        *,
        nodes: Iterable[Node] = (),
        order: Sequence[Node] | None = None,
    ) -> None:
        index: dict[Node, int] = {}
        names: list[Node] = []

        def add(v: Node) -> int:
            try:
                i = index.get(v)
            except TypeError:
                raise GraphError(f"nodes must be hashable, got {v!r} ({type(v).__name__})") from None
            if i is None:
                i = index[v] = len(names)
                names.append(v)
            return i

        for v in nodes:
            add(v)
        directed_ids = [self._edge_ids(e, "directed", add) for e in directed]
        bidirected_ids = [self._edge_ids(e, "bidirected", add) for e in bidirected]
        n = len(names)
        pa: list[set[int]] = [set() for _ in range(n)]
        ch: list[set[int]] = [set() for _ in range(n)]
        sp: list[set[int]] = [set() for _ in range(n)]
        for a, b in directed_ids:
            pa[b].add(a)
            ch[a].add(b)
        for a, b in bidirected_ids:
            sp[a].add(b)
            sp[b].add(a)
        self._nodes: list[Node] = names
        self._index = index
        self._pa: list[tuple[int, ...]] = [tuple(sorted(s)) for s in pa]
        self._ch: list[tuple[int, ...]] = [tuple(sorted(s)) for s in ch]
        self._sp: list[tuple[int, ...]] = [tuple(sorted(s)) for s in sp]
        latent_ids = set()
        for v in latent:
            if v not in self:
                raise GraphError(f"latent node {v!r} is not in the diagram")
            latent_ids.add(index[v])
        self._latent = frozenset(latent_ids)
        self._set_order(self._topological_order(order), explicit=order is not None)

    @classmethod
    def from_indices(
        cls,
        nodes: Sequence[Node],
        directed: Iterable[tuple[int, int]],
        bidirected: Iterable[tuple[int, int]] = (),
        latent: Iterable[int] = (),
    ) -> CausalDiagram:
        """A diagram over ``nodes``, taken as its (explicit, topological) order, with edges and
        latent nodes given by position in ``nodes``. It skips the name lookups of the main
        constructor, which dominate on long unrolled diagrams.

        Raises:
            GraphError: on an unhashable or repeated node, a position out of range, a
                directed edge that does not point forward in ``nodes``, or a bidirected
                self-loop.

        Examples:
            >>> CausalDiagram.from_indices(["Z", "X", "Y"], [(0, 1), (1, 2)], [(0, 2)]).bidirected_edges
            (('Z', 'Y'),)
        """
        names = list(nodes)
        try:
            index = {v: i for i, v in enumerate(names)}
        except TypeError:
            bad = next(v for v in names if not isinstance(v, Hashable))
            raise GraphError(f"nodes must be hashable, got {bad!r} ({type(bad).__name__})") from None
        if len(index) != len(names):
            raise GraphError(f"node {next(v for i, v in enumerate(names) if index[v] != i)!r} is listed twice")
        n = len(names)
        pa: list[set[int]] = [set() for _ in range(n)]
        ch: list[set[int]] = [set() for _ in range(n)]
        sp: list[set[int]] = [set() for _ in range(n)]
        for a, b in directed:
            if not 0 <= a < b < n:
                raise GraphError(f"directed edge {(a, b)} must point forward within the {n} nodes")
            pa[b].add(a)
            ch[a].add(b)
        for a, b in bidirected:
            if not (0 <= a < n and 0 <= b < n) or a == b:
                raise GraphError(f"bidirected edge {(a, b)} must join two distinct nodes among the {n}")
            sp[a].add(b)
            sp[b].add(a)
        latent_ids = frozenset(latent)
        if not all(0 <= i < n for i in latent_ids):
            raise GraphError(f"latent positions must lie within the {n} nodes")
        diagram = object.__new__(cls)
        diagram._nodes = names
        diagram._index = index
        diagram._pa = [tuple(sorted(x)) for x in pa]
        diagram._ch = [tuple(sorted(x)) for x in ch]
        diagram._sp = [tuple(sorted(x)) for x in sp]
        diagram._latent = latent_ids
        diagram._set_order(list(range(n)), explicit=True)
        return diagram

    def _set_order(self, order: list[int], explicit: bool) -> None:
        self._order = order
        self._rank = [0] * len(order)
        for r, i in enumerate(order):
            self._rank[i] = r
        self._explicit_order = explicit

    # ------------------------------------------------------------------ construction
    @staticmethod
    def _edge_ids(edge: Any, kind: str, add: Callable[[Node], int]) -> tuple[int, int]:
        try:
            a, b = edge
        except (TypeError, ValueError):
            raise GraphError(f"a {kind} edge must be a pair (a, b), got {edge!r}") from None
        if a == b:
            raise GraphError(f"{kind} self-loop on {a!r}")
        return add(a), add(b)

    def _topological_order(self, order: Sequence[Node] | None) -> list[int]:
        n = len(self._nodes)
        if order is not None:
            ids = []
            for v in order:
                if v not in self:
                    raise GraphError(f"order names {v!r}, which is not in the diagram")
                ids.append(self._index[v])
            if len(ids) != n or len(set(ids)) != n:
                raise GraphError("order must list every node of the diagram exactly once")
            rank = {v: r for r, v in enumerate(ids)}
            for b in range(n):
                for a in self._pa[b]:
                    if rank[a] > rank[b]:
                        raise GraphError(
                            f"order puts {self._nodes[b]!r} before its parent {self._nodes[a]!r}"
                        )
            return ids
        indegree = [len(p) for p in self._pa]
        heap = [i for i in range(n) if indegree[i] == 0]
        heapq.heapify(heap)
        result = []
        while heap:
            v = heapq.heappop(heap)
            result.append(v)
            for c in self._ch[v]:
                indegree[c] -= 1
                if indegree[c] == 0:
                    heapq.heappush(heap, c)
        if len(result) < n:
            raise GraphError(f"directed cycle: {' -> '.join(map(repr, self._find_cycle(indegree)))}")
        return result

    def _find_cycle(self, indegree: list[int]) -> list[Node]:
        # Every node left with positive indegree has a parent that is also left: walking
        # parents from any of them must revisit a node.
        v = next(i for i, d in enumerate(indegree) if d > 0)
        seen: dict[int, int] = {}
        path: list[int] = []
        while v not in seen:
            seen[v] = len(path)
            path.append(v)
            v = next(p for p in self._pa[v] if indegree[p] > 0)
        cycle = path[seen[v] :][::-1]
        return [self._nodes[i] for i in cycle + cycle[:1]]

    # ------------------------------------------------------------------ conversion helpers
    def _id(self, v: Node) -> int:
        try:
            return self._index[v]
        except (KeyError, TypeError):
            raise GraphError(f"unknown node {v!r}") from None

    def _ids(self, vs: Node | Iterable[Node]) -> set[int]:
        """A single node (when it is one of ours) or an iterable of nodes."""
        try:
            if vs in self._index:
                return {self._index[vs]}
        except TypeError:
            pass
        if isinstance(vs, str):
            raise GraphError(f"unknown node {vs!r}")
        return {self._id(v) for v in vs}

    def _names(self, ids: Iterable[int]) -> frozenset[Node]:
        return frozenset(self._nodes[i] for i in ids)

    def _sorted(self, ids: Iterable[int]) -> tuple[Node, ...]:
        return tuple(self._nodes[i] for i in sorted(ids, key=self._rank.__getitem__))

    # ------------------------------------------------------------------ basic structure
    @property
    def nodes(self) -> tuple[Node, ...]:
        """All nodes in topological order."""
        return tuple(self._nodes[i] for i in self._order)

    @property
    def latent(self) -> frozenset[Node]:
        return self._names(self._latent)

    @property
    def observed(self) -> frozenset[Node]:
        return self._names(i for i in range(len(self._nodes)) if i not in self._latent)

    @property
    def directed_edges(self) -> tuple[tuple[Node, Node], ...]:
        return tuple((self._nodes[a], self._nodes[b]) for b in self._order for a in self._pa[b])

    @property
    def bidirected_edges(self) -> tuple[tuple[Node, Node], ...]:
        """Each bidirected edge once, as ``(earlier, later)`` in topological order."""
        rank = self._rank
        return tuple(
            (self._nodes[a], self._nodes[b]) for b in self._order for a in self._sp[b] if rank[a] < rank[b]
        )

    def __len__(self) -> int:
        return len(self._nodes)

    def __contains__(self, v: object) -> bool:
        try:
            return v in self._index
        except TypeError:
            return False

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(nodes={len(self)}, directed={sum(map(len, self._pa))}, "
            f"bidirected={sum(map(len, self._sp)) // 2}, latent={len(self._latent)})"
        )

    def parents(self, v: Node) -> frozenset[Node]:
        return self._names(self._pa[self._id(v)])

    def children(self, v: Node) -> frozenset[Node]:
        return self._names(self._ch[self._id(v)])

    def spouses(self, v: Node) -> frozenset[Node]:
        """Nodes joined to ``v`` by a bidirected edge."""
        return self._names(self._sp[self._id(v)])

    def ancestors(self, vs: Node | Iterable[Node]) -> frozenset[Node]:
        """``vs`` and every node with a directed path into ``vs``."""
        return self._names(_ancestor_ids(self._pa, self._ids(vs)))

    def descendants(self, vs: Node | Iterable[Node]) -> frozenset[Node]:
        """``vs`` and every node reachable from ``vs`` by a directed path."""
        return self._names(_ancestor_ids(self._ch, self._ids(vs)))

    def topological_order(self) -> tuple[Node, ...]:
        return self.nodes

    @property
    def has_explicit_order(self) -> bool:
        """Whether the diagram was built with an ``order`` (else its order is a default
        topological sort, and "before" is decided per query from the actions)."""
        return self._explicit_order

    def with_order(self, order: Sequence[Node]) -> CausalDiagram:
        """The same diagram with an explicit topological ``order`` of all its nodes.

        Raises:
            GraphError: when ``order`` misses a node, names an unknown one, or puts a node
                before one of its parents.
        """
        copy = object.__new__(CausalDiagram)
        copy.__dict__.update(self.__dict__)
        copy._set_order(self._topological_order(order), explicit=True)
        return copy

    def before(self, v: Node) -> frozenset[Node]:
        """Nodes strictly earlier than ``v`` in the topological order."""
        r = self._rank[self._id(v)]
        return self._names(self._order[:r])

    # ------------------------------------------------------------------ confounding structure
    def _c_component_ids(self, start: int, allowed: Callable[[int], bool] | None = None) -> set[int]:
        comp = {start}
        stack = [start]
        while stack:
            for s in self._sp[stack.pop()]:
                if s not in comp and (allowed is None or allowed(s)):
                    comp.add(s)
                    stack.append(s)
        return comp

    def c_component(self, v: Node) -> frozenset[Node]:
        """The confounded component of ``v``: nodes joined to it by bidirected paths (Def. 3)."""
        return self._names(self._c_component_ids(self._id(v)))

    def pa_plus(self, v: Node) -> frozenset[Node]:
        """Extended parents ``Pa(C(v)) \\ {v}`` in ``G(v)`` (Tian & Pearl, 2002).

        ``G(v)`` is the subgraph induced by ``v`` and its predecessors in the topological
        order and ``C(v)`` the C-component of ``v`` there; ``Pa(S)`` is ``S`` together with
        the parents of ``S`` (Tian & Pearl's capitalised convention), so the result holds
        every variable collider-connected to ``v`` and their parents, as the paper says.
        Call it on a :meth:`latent_projection` to get the paper's pa+.
        """
        i = self._id(v)
        r = self._rank[i]
        comp = self._c_component_ids(i, lambda u: self._rank[u] < r)
        result = set(comp)
        for u in comp:
            result.update(self._pa[u])
        result.discard(i)
        return self._names(result)

    def _ch_plus_ids(self, i: int) -> set[int]:
        latent = self._latent
        found: set[int] = set()
        seen_latent: set[int] = set()
        stack = [i]
        while stack:
            for c in self._ch[stack.pop()]:
                if c in latent:
                    if c not in seen_latent:
                        seen_latent.add(c)
                        stack.append(c)
                else:
                    found.add(c)
        return found

    def ch_plus(self, v: Node) -> frozenset[Node]:
        """Effective children: observed nodes reached by directed paths whose interior is latent
        (the children of ``v`` in the latent projection onto the observed nodes)."""
        return self._names(self._ch_plus_ids(self._id(v)))

    # ------------------------------------------------------------------ derived diagrams
    def subgraph(self, vs: Iterable[Node]) -> CausalDiagram:
        """The subgraph induced by ``vs`` (latent flags and order kept)."""
        keep = self._ids(vs)
        names = self._nodes
        return CausalDiagram(
            [(names[a], names[b]) for b in keep for a in self._pa[b] if a in keep],
            [(names[a], names[b]) for b in keep for a in self._sp[b] if a in keep and a < b],
            [names[i] for i in keep & self._latent],
            nodes=[names[i] for i in self._order if i in keep],
            order=[names[i] for i in self._order if i in keep],
        )

    def ancestral_subgraph(self, targets: Node | Iterable[Node]) -> CausalDiagram:
        """The subgraph induced by the ancestors of ``targets`` (e.g. ``G^Y``)."""
        return self.subgraph(self.ancestors(targets))

    def latent_projection(self, keep: Iterable[Node] | None = None) -> CausalDiagram:
        """Verma & Pearl's latent projection onto ``keep`` (default: the observed nodes).

        ``a -> b`` when a directed path from ``a`` to ``b`` has all its interior outside
        ``keep``; ``a <-> b`` when a path between them with interior outside ``keep`` has
        arrowheads at both ends and no interior collider (bidirected edges included). Such
        a path always has a "top": a dropped node with dropped-interior directed paths to
        both ends, or a bidirected edge between the ends of two such directed paths.
        Latent flags of kept nodes are kept; conditional independences and ancestral
        relations among kept nodes are preserved.
        """
        keep_ids = self._ids(self.observed if keep is None else keep)
        reach: dict[int, set[int]] = {}  # dropped node -> kept nodes first hit going down

        def down(i: int) -> set[int]:
            return {i} if i in keep_ids else reach[i]

        for i in reversed(self._order):
            if i not in keep_ids:
                hit: set[int] = set()
                for c in self._ch[i]:
                    hit |= down(c)
                reach[i] = hit
        directed = set()
        for a in keep_ids:
            for c in self._ch[a]:
                directed.update((a, b) for b in down(c))
        bidirected: set[tuple[int, int]] = set()

        def join(ends_a: set[int], ends_b: set[int]) -> None:
            bidirected.update((min(a, b), max(a, b)) for a in ends_a for b in ends_b if a != b)

        for i, hit in reach.items():
            if not any(p not in keep_ids for p in self._pa[i]):  # tops only: others are subsumed
                join(hit, hit)
        for a in range(len(self._nodes)):
            for b in self._sp[a]:
                if a < b:
                    join(down(a), down(b))
        names = self._nodes
        order = [names[i] for i in self._order if i in keep_ids]
        return CausalDiagram(
            [(names[a], names[b]) for a, b in directed],
            [(names[a], names[b]) for a, b in bidirected],
            [names[i] for i in keep_ids & self._latent],
            nodes=order,
            order=order,
        )

    def to_networkx(self) -> Any:
        """A ``networkx.DiGraph`` in which each bidirected edge ``a <-> b`` becomes an explicit
        latent :class:`Confounder` node with edges into ``a`` and ``b``; every node carries a
        boolean ``latent`` attribute."""
        import networkx as nx

        graph = nx.DiGraph()
        for i in self._order:
            graph.add_node(self._nodes[i], latent=i in self._latent)
        graph.add_edges_from(self.directed_edges)
        for a, b in self.bidirected_edges:
            u = Confounder(a, b)
            graph.add_node(u, latent=True)
            graph.add_edge(u, a)
            graph.add_edge(u, b)
        return graph

    # ------------------------------------------------------------------ d-separation
    def _prepare_query(
        self, xs: Node | Iterable[Node], ys: Node | Iterable[Node], zs: Node | Iterable[Node]
    ) -> tuple[set[int], set[int], set[int]]:
        z = self._ids(zs)
        return self._ids(xs) - z, self._ids(ys) - z, z

    def d_connecting_path(
        self, xs: Node | Iterable[Node], ys: Node | Iterable[Node], zs: Node | Iterable[Node] = ()
    ) -> tuple[Node, ...] | None:
        """A shortest path from ``xs`` to ``ys`` left open by ``zs``, or None if d-separated.

        Nodes of ``zs`` are dropped from ``xs`` and ``ys`` first (a variable is independent
        of everything given itself).
        """
        x, y, z = self._prepare_query(xs, ys, zs)
        if not x or not y:
            return None
        common = x & y
        if common:
            return (self._nodes[min(common)],)
        path = _find_open_path(
            self._pa, self._ch, self._sp, x, z.__contains__, _ancestor_ids(self._pa, z).__contains__, y.__contains__
        )
        return None if path is None else tuple(self._nodes[i] for i in path)

    def is_d_separated(
        self, xs: Node | Iterable[Node], ys: Node | Iterable[Node], zs: Node | Iterable[Node] = ()
    ) -> bool:
        """Whether ``zs`` d-separates ``xs`` from ``ys`` (bidirected edges count as latent
        common causes). Linear in the size of the diagram: every (node, entered-through-
        arrowhead?) state is expanded once."""
        return self.d_connecting_path(xs, ys, zs) is None

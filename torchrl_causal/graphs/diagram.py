"""Causal diagrams with directed and bidirected edges (semi-Markovian DAGs).

Nodes are arbitrary hashables. Internally every node is an int (its insertion index) and
adjacency is stored as tuples of ints, because the unrolled diagrams of long episodes
have tens of thousands of nodes and every search below must stay linear in their size;
:attr:`CausalDiagram.indexed` hands that representation to the graph algorithms.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Hashable, Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property
from types import MappingProxyType
from typing import Any, cast

from .errors import GraphError
from .indexed import IndexedDiagram, find_open_path, reach

Node = Hashable

__all__ = ["CausalDiagram", "Confounder"]


@dataclass(frozen=True)
class Confounder:
    """The explicit latent common cause that :meth:`CausalDiagram.to_networkx` puts in place
    of a bidirected edge ``a <-> b``."""

    a: Node
    b: Node


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
        self.__dict__.pop("indexed", None)  # a copy made by with_order gets its own view
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
                        raise GraphError(f"order puts {self._nodes[b]!r} before its parent {self._nodes[a]!r}")
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
        # Not one of our nodes, so the iterable of them that the signature allows.
        return {self._id(v) for v in cast(Iterable[Node], vs)}

    def _names(self, ids: Iterable[int]) -> frozenset[Node]:
        return frozenset(self._nodes[i] for i in ids)

    def _sorted(self, ids: Iterable[int]) -> tuple[Node, ...]:
        return tuple(self._nodes[i] for i in sorted(ids, key=self._rank.__getitem__))

    # ------------------------------------------------------------------ basic structure
    @cached_property
    def indexed(self) -> IndexedDiagram:
        """The diagram as ints, read-only (see :class:`~torchrl_causal.graphs.indexed.IndexedDiagram`):
        what the criteria and the adjustment search run on."""
        return IndexedDiagram(
            nodes=tuple(self._nodes),
            index=MappingProxyType(self._index),
            parents=tuple(self._pa),
            children=tuple(self._ch),
            siblings=tuple(self._sp),
            latent=self._latent,
            order=tuple(self._order),
            rank=tuple(self._rank),
        )

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
        return tuple((self._nodes[a], self._nodes[b]) for b in self._order for a in self._sp[b] if rank[a] < rank[b])

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
        ids = self._ids(vs)
        return self._names(ids | reach(self._pa, ids))

    def descendants(self, vs: Node | Iterable[Node]) -> frozenset[Node]:
        """``vs`` and every node reachable from ``vs`` by a directed path."""
        ids = self._ids(vs)
        return self._names(ids | reach(self._ch, ids))

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
        return {start} | reach(self._sp, [start], within=allowed)

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
        return {c for c in reach(self._ch, [i], through=latent.__contains__) if c not in latent}

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
        directed: set[tuple[int, int]] = set()
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
        path = find_open_path(self._pa, self._ch, self._sp, x, z.__contains__, (z | reach(self._pa, z)).__contains__, y.__contains__)
        return None if path is None else tuple(self._nodes[i] for i in path)

    def is_d_separated(self, xs: Node | Iterable[Node], ys: Node | Iterable[Node], zs: Node | Iterable[Node] = ()) -> bool:
        """Whether ``zs`` d-separates ``xs`` from ``ys`` (bidirected edges count as latent
        common causes). Linear in the size of the diagram: every (node, entered-through-
        arrowhead?) state is expanded once."""
        return self.d_connecting_path(xs, ys, zs) is None

"""A diagram as integers: the public, read-only view the graph algorithms work on, and the
searches they share.

Every node of a :class:`~torchrl_causal.graphs.CausalDiagram` is an int (its insertion
index) and its adjacency is tuples of ints, because the unrolled diagrams of long episodes
have tens of thousands of nodes and every search must stay linear in their size.
:class:`IndexedDiagram` hands that adjacency out read-only; :func:`reach` walks it,
:class:`UnionFind` merges components of it and :func:`find_open_path` runs Bayes-ball on it.

Examples:
    >>> from torchrl_causal.graphs import CausalDiagram
    >>> g = CausalDiagram([("Z", "X"), ("X", "Y")], bidirected=[("Z", "Y")], latent=["Z"]).indexed
    >>> [g.nodes[i] for i in g.order], g.parents[g.id("Y")], g.siblings[g.id("Y")]
    (['Z', 'X', 'Y'], (1,), (0,))
    >>> sorted(g.names(reach(g.children, [g.id("Z")])))
    ['X', 'Y']
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from .errors import GraphError

Node = Hashable
Item = TypeVar("Item", bound=Hashable)

__all__ = ["IndexedDiagram", "UnionFind", "find_open_path", "reach", "shortcut_walk"]


@dataclass(frozen=True)
class IndexedDiagram:
    """A diagram's nodes as ints, read-only: what the criteria and the adjustment search on.

    Attributes:
        nodes: node ``i``'s name, by insertion index.
        index: name -> index.
        parents, children: directed neighbours of node ``i`` (sorted tuples).
        siblings: nodes joined to node ``i`` by a bidirected edge.
        latent: the indices of the latent nodes.
        order: the indices in topological order (the diagram's temporal order).
        rank: node ``i``'s position in ``order``.
    """

    nodes: Sequence[Node]
    index: Mapping[Node, int]
    parents: Sequence[tuple[int, ...]]
    children: Sequence[tuple[int, ...]]
    siblings: Sequence[tuple[int, ...]]
    latent: frozenset[int]
    order: Sequence[int]
    rank: Sequence[int]

    def id(self, node: Node) -> int:
        """The index of ``node``.

        Raises:
            GraphError: naming a node that is not in the diagram.
        """
        try:
            return self.index[node]
        except (KeyError, TypeError):
            raise GraphError(f"unknown node {node!r}") from None

    def names(self, ids: Iterable[int]) -> frozenset[Node]:
        return frozenset(self.nodes[i] for i in ids)

    def in_order(self, ids: Iterable[int]) -> tuple[Node, ...]:
        """The names of ``ids`` in temporal order."""
        return tuple(self.nodes[i] for i in sorted(ids, key=self.rank.__getitem__))


def reach(
    neighbours: Sequence[Iterable[int]],
    seeds: Iterable[int],
    *,
    through: Callable[[int], bool] | None = None,
    within: Callable[[int], bool] | None = None,
) -> set[int]:
    """Every node at the end of a walk of one step or more from ``seeds`` along ``neighbours``.

    ``within`` bounds the nodes a walk may enter; ``through`` the nodes it may go on from
    (a seed always may). A seed is in the result only when a walk returns to it. Linear in
    the edges walked.

    Examples:
        >>> chain = [(1,), (2,), (3,), ()]                      # 0 -> 1 -> 2 -> 3
        >>> sorted(reach(chain, [0])), sorted(reach(chain, [0], through=lambda v: v < 2))
        ([1, 2, 3], [1, 2])
        >>> sorted(reach(chain, [0], within=lambda v: v != 2))
        [1]
    """
    found: set[int] = set()
    stack = list(seeds)
    while stack:
        for u in neighbours[stack.pop()]:
            if u not in found and (within is None or within(u)):
                found.add(u)
                if through is None or through(u):
                    stack.append(u)
    return found


class UnionFind(Generic[Item]):
    """Disjoint sets over hashable items, with path halving.

    Examples:
        >>> sets = UnionFind(range(4))
        >>> sets.union(0, 1), sets.union(2, 3), sets.union(1, 0)
        (0, 2, None)
        >>> sets.find(0) == sets.find(2), sets.find(0) == sets.find(1)
        (False, True)
    """

    def __init__(self, items: Iterable[Item] = ()) -> None:
        self._root: dict[Item, Item] = {v: v for v in items}

    def find(self, item: Item) -> Item:
        root = self._root
        while root[item] != item:
            root[item] = root[root[item]]
            item = root[item]
        return item

    def union(self, a: Item, b: Item) -> Item | None:
        """Merges the sets of ``a`` and ``b`` under ``b``'s representative; returns ``a``'s
        former representative (whatever a caller keeps per set moves from it), or None when
        the two were one set already."""
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return None
        self._root[ra] = rb
        return ra


def shortcut_walk(walk: list[int]) -> list[int]:
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


def find_open_path(
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
    # A target is returned when it is queued, not when it comes out of the queue: the queue
    # is FIFO, so the first target queued is the first that would come out, with the same
    # path, and the rest of the search (a window's later actions, say) is never expanded.
    while queue:
        state = queue.popleft()
        v = state >> 1
        origin = prev[state] == -1
        moves: list[int] = []
        # children[v] is read only where the walk goes on down (it may be computed on demand)
        if state & 1:
            if collider_open(v):
                moves.extend(2 * p for p in parents[v] if p != cut)
                moves.extend(2 * s + 1 for s in spouses[v])
            if not blocked(v) and v != cut:
                moves.extend(2 * c + 1 for c in children[v])
        elif origin or not blocked(v):
            if v != cut:
                moves.extend(2 * c + 1 for c in children[v])
            if fixed is None or not fixed(v):
                moves.extend(2 * p for p in parents[v] if p != cut)
                moves.extend(2 * s + 1 for s in spouses[v])
        for nxt in moves:
            if nxt in prev or (inside is not None and not inside(nxt >> 1)):
                continue
            if nxt & 1 and fixed is not None and fixed(nxt >> 1):
                continue
            prev[nxt] = state
            if is_target(nxt >> 1):
                walk = []
                while nxt != -1:
                    walk.append(nxt >> 1)
                    nxt = prev[nxt]
                return shortcut_walk(walk[::-1])
            queue.append(nxt)
    return None

"""The graph engine against independent facts on thousands of seeded random small diagrams:
a brute-force search over every family of adjustment sets, and a second implementation of
Definition 2 (moralised ancestral graphs of the explicit-confounder DAG, with networkx).
Neither uses the engine's own d-separation."""

from __future__ import annotations

import itertools
import random

import networkx as nx
import pytest

from torchrl_causal.graphs import (
    CausalDiagram,
    NotImitableError,
    TimeSliceTemplate,
    exact_adjustment,
    find_adjustment,
    find_ox,
    sequential_pi_backdoor,
)

CASES = 3000
NETWORKX_CASES = 600  # the networkx checker is the slow one: it sees a prefix of the cases


def random_diagram(rng: random.Random) -> tuple[CausalDiagram, list[str]]:
    """4-7 nodes v0, v1, ... and "Y" last, 1-3 actions, the other nodes latent or observed,
    directed edges forward in index order, bidirected edges anywhere."""
    n = rng.randint(4, 7)
    names = [f"v{i}" for i in range(n - 1)] + ["Y"]
    actions = sorted(rng.sample(range(n - 1), rng.randint(1, min(3, n - 1))))
    latent = [names[i] for i in range(n - 1) if i not in actions and rng.random() < 0.35]
    p_directed, p_bidirected = rng.choice([0.3, 0.45, 0.6]), rng.choice([0.1, 0.2, 0.3])
    pairs = list(itertools.combinations(names, 2))
    directed = [p for p in pairs if rng.random() < p_directed]
    bidirected = [p for p in pairs if rng.random() < p_bidirected]
    diagram = CausalDiagram(directed, bidirected, latent, nodes=names, order=names)
    return diagram, [names[i] for i in actions]


@pytest.fixture(scope="module")
def cases() -> list[tuple[CausalDiagram, list[str]]]:
    rng = random.Random(12)
    return [random_diagram(rng) for _ in range(CASES)]


# ---------------------------------------------------------------------- Definition 2, twice
def manipulated(diagram: CausalDiagram, actions: list, t: int, family: dict) -> nx.DiGraph:
    """``G'_t`` as an explicit DAG: bidirected edges are latent confounder nodes, the actions
    after ``actions[t]`` lose every incoming edge and get their sets as parents."""
    dag = diagram.to_networkx()
    for later in actions[t + 1 :]:
        dag.remove_edges_from(list(dag.in_edges(later)))
        dag.add_edges_from((z, later) for z in family[later])
    return dag


def moral_separated(dag: nx.DiGraph, x, y, given: set) -> bool:
    """Lauritzen's criterion: ``x`` and ``y`` are d-separated by ``given`` iff they are
    disconnected in the moral graph of the ancestral set of ``{x, y} ∪ given``, minus ``given``."""
    keep = {x, y} | given
    for v in list(keep):
        keep |= nx.ancestors(dag, v)
    moral = nx.moral_graph(dag.subgraph(keep))
    moral.remove_nodes_from(given)
    return not nx.has_path(moral, x, y)


def definition2_failures(diagram: CausalDiagram, actions: list, reward, family: dict) -> list:
    failing = []
    for t, x in enumerate(actions):
        dag = manipulated(diagram, actions, t, family)
        if reward not in nx.descendants(dag, x):
            continue
        dag.remove_edges_from(list(dag.out_edges(x)))
        if not moral_separated(dag, x, reward, set(family[x])):
            failing.append(x)
    return failing


class Canonical:
    """The explicit-confounder DAG as parent bitmasks, for the brute force: node ``i`` of the
    diagram's order is bit ``i``, bidirected edge ``j`` a latent parent ``n + j`` of both ends."""

    def __init__(self, diagram: CausalDiagram, actions: list) -> None:
        self.names = list(diagram.nodes)
        index = {v: i for i, v in enumerate(self.names)}
        n = len(self.names)
        bidirected = diagram.bidirected_edges
        self.parents = [0] * (n + len(bidirected))
        for a, b in diagram.directed_edges:
            self.parents[index[b]] |= 1 << index[a]
        for j, (a, b) in enumerate(bidirected):
            self.parents[index[a]] |= 1 << (n + j)
            self.parents[index[b]] |= 1 << (n + j)
        self.reward = index["Y"]
        self.actions = [index[x] for x in actions]
        hidden = {index[v] for v in diagram.latent}
        self.observed_before = {x: sum(1 << i for i in range(x) if i not in hidden) for x in self.actions}


def bits(mask: int):
    while mask:
        low = mask & -mask
        mask ^= low
        yield low.bit_length() - 1


def ancestors(parents: list[int], mask: int) -> int:
    found, frontier = mask, mask
    while frontier:
        v = next(bits(frontier))
        frontier &= frontier - 1
        new = parents[v] & ~found
        found |= new
        frontier |= new
    return found


def separated(parents: list[int], x: int, y: int, given: int) -> bool:
    """Lauritzen's criterion on bitmasks."""
    keep = ancestors(parents, (1 << x) | (1 << y) | given)
    neighbours = [0] * len(parents)
    for v in bits(keep):
        for u in bits(parents[v]):
            neighbours[v] |= 1 << u
            neighbours[u] |= (1 << v) | (parents[v] & ~(1 << u))
    reached = frontier = 1 << x
    while frontier:
        v = next(bits(frontier))
        frontier &= frontier - 1
        new = neighbours[v] & ~reached & ~given
        if new >> y & 1:
            return False
        reached |= new
        frontier |= new
    return True


def subsets(mask: int):
    members = [1 << i for i in bits(mask)]
    for r in range(len(members) + 1):
        for chosen in itertools.combinations(members, r):
            yield sum(chosen)


def bit_definition2_holds(diagram: CausalDiagram, actions: list, family: dict) -> bool:
    dag = Canonical(diagram, actions)
    index = {v: i for i, v in enumerate(dag.names)}
    sets = {index[x]: sum(1 << index[v] for v in family[x]) for x in actions}
    parents = list(dag.parents)
    for x in reversed(dag.actions):
        if ancestors(parents, 1 << dag.reward) >> x & 1:
            if not separated([p & ~(1 << x) for p in parents], x, dag.reward, sets[x]):
                return False
        parents[x] = sets[x]
    return True


def admissible_family(diagram: CausalDiagram, actions: list) -> dict | None:
    """A family meeting Definition 2 by exhaustive search, latest action first, or None.

    An action that does not cause the reward in its ``G'_t`` gets the empty set without
    loss: its later-action ancestors and descendants are fixed by then, and nothing it is
    a parent of can reach the reward or an earlier action's set, so its set changes no
    earlier check.
    """
    dag = Canonical(diagram, actions)

    def search(i: int, parents: list[int]) -> dict | None:
        if i < 0:
            return {}
        x = dag.actions[i]
        options = (
            [0]
            if not ancestors(parents, 1 << dag.reward) >> x & 1
            else [z for z in subsets(dag.observed_before[x]) if separated([p & ~(1 << x) for p in parents], x, dag.reward, z)]
        )
        for z in options:
            earlier = search(i - 1, [z if v == x else p for v, p in enumerate(parents)])
            if earlier is not None:
                return {**earlier, x: z}
        return None

    found = search(len(dag.actions) - 1, dag.parents)
    if found is None:
        return None
    return {dag.names[x]: {dag.names[v] for v in bits(z)} for x, z in found.items()}


# ---------------------------------------------------------------------- the tests
def describe(diagram: CausalDiagram, actions: list) -> str:
    return f"actions={actions}, directed={diagram.directed_edges}, bidirected={diagram.bidirected_edges}, latent={sorted(diagram.latent)}"


def test_find_ox_verdict_matches_brute_force(cases):
    disagreements = []
    imitable_count = 0
    for i, (diagram, actions) in enumerate(cases):
        family = admissible_family(diagram, actions)
        if family is not None:
            imitable_count += 1
            if i < NETWORKX_CASES:
                assert not definition2_failures(diagram, actions, "Y", family), describe(diagram, actions)
        ox = find_ox(diagram, actions, "Y")
        verdict = all(x in ox for x in actions if x in diagram.ancestors("Y"))
        if verdict != (family is not None):
            disagreements.append(describe(diagram, actions))
    assert not disagreements, f"{len(disagreements)} of {len(cases)} disagree, e.g. {disagreements[0]}"
    # the sample has both answers in bulk, so agreement is not vacuous
    assert 0.3 * len(cases) < imitable_count < 0.8 * len(cases)


def test_adjustment_sets_pass_both_checkers(cases):
    refused = certified = 0
    for i, (diagram, actions) in enumerate(cases):
        try:
            result = find_adjustment(diagram, actions, "Y")
        except NotImitableError as err:
            refused += 1
            certified += bool(err.witness)
            continue
        family = result.family
        assert sequential_pi_backdoor(diagram, actions, "Y", family).holds, describe(diagram, actions)
        assert bit_definition2_holds(diagram, actions, family), describe(diagram, actions)
        if i < NETWORKX_CASES:
            assert not definition2_failures(diagram, actions, "Y", family), describe(diagram, actions)
    assert refused and certified > 0.9 * refused


def test_certificates_hold_under_every_family(cases):
    """A certificate names an action that fails whatever the sets: in the graph where the
    later actions lose every incoming edge (the most favourable ``G'_t``), it causes the
    reward and no set of observed nodes before it separates the two."""
    checked = 0
    for diagram, actions in cases:
        try:
            find_adjustment(diagram, actions, "Y")
        except NotImitableError as err:
            if not err.witness:
                continue
            x = err.witness[0]
            later = actions[actions.index(x) + 1 :]
            dag = Canonical(diagram, actions)
            index = {v: i for i, v in enumerate(dag.names)}
            favourable = [0 if v < len(dag.names) and dag.names[v] in later else p for v, p in enumerate(dag.parents)]
            assert ancestors(favourable, 1 << dag.reward) >> index[x] & 1, describe(diagram, actions)
            cut = [p & ~(1 << index[x]) for p in favourable]
            assert not any(separated(cut, index[x], dag.reward, z) for z in subsets(dag.observed_before[index[x]])), describe(
                diagram, actions
            )
            assert err.witness[-1] == "Y" and x in err.actions
            checked += 1
    assert checked > 100


# ---------------------------------------------------------------------- the cases
def test_intermediate_latents_stay_in_the_component_graph():
    # X -> L -> O -> Y, X <-> L, L <-> Y, L latent: X <-> L -> O -> Y cannot be blocked.
    tiny = CausalDiagram([("X", "L"), ("L", "O"), ("O", "Y")], [("X", "L"), ("L", "Y")], ["L"])
    assert admissible_family(tiny.with_order(["X", "L", "O", "Y"]), ["X"]) is None
    assert "X" not in find_ox(tiny, ["X"], "Y")
    with pytest.raises(NotImitableError) as info:
        find_adjustment(tiny, ["X"], "Y")
    assert info.value.witness == ("X", "L", "O", "Y")
    template = TimeSliceTemplate(
        variables=["s", "o", "x"],
        action="x",
        observed=["o", "x"],
        directed=[("s", "x", 0), ("s", "o", 0), ("x", "s", 1)],
        reward_parents=["o"],
        reward_bidirected=["s"],
        reward_slices="all",
    )
    for horizon in (1, 5, 40):
        with pytest.raises(NotImitableError) as info:
            exact_adjustment(template, horizon)
        assert info.value.witness == (("x", horizon - 1), ("s", horizon - 1), "Y")


def test_action_outgoing_edges_are_cut_in_the_component_graph():
    template = TimeSliceTemplate(
        variables=["s", "x"],
        action="x",
        observed=["s", "x"],
        directed=[("s", "s", 1), ("x", "s", 1)],
        bidirected=[("s", "x", 0), ("x", "x", 1)],
        reward_parents=["s"],
        reward_slices="last",
    )
    for horizon in (2, 10, 40):
        g = template.unroll(horizon)
        actions = [("x", t) for t in range(horizon)]
        current_state = {x: {("s", x[1])} for x in actions}
        result = exact_adjustment(template, horizon)
        for family in (current_state, result.family):
            assert sequential_pi_backdoor(g, actions, "Y", family).holds
            assert bit_definition2_holds(g, actions, family)
            assert horizon > 10 or not definition2_failures(g, actions, "Y", family)

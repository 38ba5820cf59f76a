"""Building a window costs what it returns (issue 58): the rule-based verification gives the
window the listed (quadratic) one gives, on every shipped template and on random ones,
agrees with the brute-force Definition-2 checker, and the API refuses a window as long as
the horizon."""

from __future__ import annotations

import random
import time

import pytest
from test_graphs_bruteforce import bit_definition2_holds

from torchrl_causal.envs.antmaze import AntMazeEnv
from torchrl_causal.envs.humanoidmaze import HumanoidMazeEnv
from torchrl_causal.envs.route_choice import RouteChoiceEnv
from torchrl_causal.envs.rover_maze import RoverMazeEnv
from torchrl_causal.errors import TorchRLCausalError
from torchrl_causal.graphs import GraphError, TimeSliceTemplate, WindowSizeError, sequential_pi_backdoor, windowed_adjustment

SHIPPED = {
    "routechoice": RouteChoiceEnv.slice_template(),
    "rovermaze": RoverMazeEnv.slice_template(),
    "antmaze": AntMazeEnv.slice_template(),
    "humanoidmaze": HumanoidMazeEnv.slice_template(),
}


def imitable_variant(template: TimeSliceTemplate) -> TimeSliceTemplate:
    """No persistent latent, reward at the end: exact mode then returns windows (it refuses
    every shipped template), so that path is compared too."""
    return template.replace(directed=[e for e in template.directed if not (e[0] == e[1] and e[0] in template.latent)], reward_slices="last")


def build(template: TimeSliceTemplate, k: int, mode: str, verification: str):
    try:
        return windowed_adjustment(template, k, mode, verification=verification)
    except GraphError as error:  # a refusal must be the same refusal, message included
        return type(error).__name__, str(error)


@pytest.mark.parametrize("name", sorted(SHIPPED))
@pytest.mark.parametrize("variant", [False, True])
@pytest.mark.parametrize("mode", ["relaxed", "exact"])
def test_rule_gives_the_listed_window_on_shipped_templates(name, variant, mode):
    template = imitable_variant(SHIPPED[name]) if variant else SHIPPED[name]
    for k in range(0, 6):
        listed = build(template, k, mode, "listed")
        assert build(template, k, mode, "rule") == listed, (name, variant, mode, k)


def random_template(rng: random.Random) -> TimeSliceTemplate:
    """Two to three states and an action, some latent, random lag-0/1/2 edges and confounders."""
    states = ["a", "b", "c"][: rng.randint(2, 3)]
    variables = [*states, "x"]
    observed = ["x", *[s for s in states if rng.random() < 0.7]]
    directed = [(rng.choice(states), "x", 0), ("x", rng.choice(states), 1)]
    for i, src in enumerate(variables):
        for dst in variables:
            lag0 = (dst != "x" and src != "x" and variables.index(dst) > i) or (dst == "x" and src != "x")
            if lag0 and rng.random() < 0.3:
                directed.append((src, dst, 0))
            if rng.random() < 0.25:
                directed.append((src, dst, rng.randint(1, 2)))
    bidirected = [(a, b, rng.randint(0, 1)) for a in variables for b in variables if a < b and rng.random() < 0.15]
    return TimeSliceTemplate(
        variables=variables,
        action="x",
        observed=observed,
        directed=directed,
        bidirected=bidirected,
        reward_parents=rng.sample(states, rng.randint(1, 2)),
        reward_bidirected=rng.sample(variables, rng.randint(0, 1)),
        reward_slices=rng.choice(["last", "all"]),
    )


def test_rule_gives_the_listed_window_on_random_templates():
    rng = random.Random(58)
    for _ in range(60):
        template = random_template(rng)
        for mode in ("relaxed", "exact"):
            for k in (0, 1, 2, 3):
                assert build(template, k, mode, "rule") == build(template, k, mode, "listed"), (template, mode, k)


def test_verification_agrees_with_brute_force_definition_2():
    # The brute force (bitmask Lauritzen criterion on the explicit-confounder DAG, no engine
    # code) on every action of small unrolled templates, for the window relaxed mode builds.
    rng = random.Random(7)
    checked = 0
    for _ in range(40):
        template = random_template(rng)
        for k in (0, 1, 2):
            window = windowed_adjustment(template, k, "relaxed")
            horizon = 3
            diagram = template.unroll(horizon)
            actions = [(template.action, t) for t in range(horizon)]
            family = {(template.action, t): window.adjustment_set(t) for t in range(horizon)}
            by_rule = windowed_adjustment(template, k, "relaxed", verification="rule")
            assert by_rule == window
            holds = sequential_pi_backdoor(diagram, actions, "Y", family).holds
            assert holds == bit_definition2_holds(diagram, actions, family), (template, k)
            checked += 1
    assert checked == 120


def test_window_construction_is_linear_in_k():
    # CPU time (not the wall clock: a loaded machine inflates that) of AntMaze's relaxed
    # window at k and 4k: quadratic would be 16x; the listed construction took ~60 s at k=800.
    template = SHIPPED["antmaze"]

    def cpu(k: int) -> float:
        start = time.process_time()
        windowed_adjustment(template, k, "relaxed")
        return time.process_time() - start

    small, large = min(cpu(50) for _ in range(2)), cpu(200)
    assert large < 8 * small + 0.2, (small, large)


def test_from_env_refuses_a_window_as_long_as_the_horizon():
    from torchrl_causal.transforms import CausalWindowTransform

    env = RoverMazeEnv(horizon=20, seed=0)
    for k in (20, 100_000):
        start = time.process_time()
        with pytest.raises(WindowSizeError, match=rf"k={k} must be < the env's horizon=20") as caught:
            CausalWindowTransform.from_env(env, k)
        assert isinstance(caught.value, TorchRLCausalError) and time.process_time() - start < 1.0
        assert "\n" not in str(caught.value)
    assert CausalWindowTransform.from_env(env, 19).window.k == 19


# ---------------------------------------------------------------------- sizes refused before allocating
@pytest.mark.parametrize("batch_size", [2.0, -1, "4", (2, 2.5), True])
def test_env_batch_sizes_are_validated(batch_size):
    from torchrl_causal.envs.base import EnvArgumentError

    with pytest.raises(EnvArgumentError, match="batch_size must be an int >= 0") as caught:
        RoverMazeEnv(batch_size=batch_size)
    assert isinstance(caught.value, TorchRLCausalError) and "\n" not in str(caught.value)


def test_mujoco_batch_beyond_memory_is_refused_before_allocating():
    import resource

    from torchrl_causal.envs.base import EnvArgumentError

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(EnvArgumentError, match=r"batch size 200000 needs 200000 MuJoCo simulations"):
        AntMazeEnv(batch_size=200_000)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 200_000  # KiB: nothing of the batch allocated

"""The smallest runs that still pass through every code path: the Hydra overrides shared by
the tests that train. A test adds its own after these, and a key it names again takes the
test's value: :func:`tiny` merges them, since the command line refuses a key given twice."""

from __future__ import annotations

ROVER = ["env=rovermaze_u", "env.horizon=40", "window.k=2"]
QUICK = ["progress_bar=false", "threads=1", "demos.episodes=6", "eval.episodes=4", "eval.num_envs=4", "eval.final_episodes=8"]
SMALL_ACTOR = ["algo.actor.hidden=16", "algo.actor.num_blocks=1"]
SOFT_Q = [
    *SMALL_ACTOR,
    "algo.critic.hidden=16",
    "algo.critic.num_blocks=1",
    "algo.total_steps=240",
    "algo.random_steps=80",
    "algo.num_envs=2",
    "algo.frames_per_batch=40",
    "algo.batch_size=32",
    "algo.buffer_size=1000",
    "algo.eval_every=120",
]
ALGO: dict[str, list[str]] = {
    "bc": [*SMALL_ACTOR, "algo.epochs=3", "algo.batch_size=64", "algo.eval_every=2"],
    "gail": [
        *SMALL_ACTOR,
        "algo.value.hidden=16",
        "algo.discriminator.hidden=16",
        "algo.rounds=2",
        "algo.episodes_per_round=2",
        "algo.batch_size=32",
        "algo.discriminator_batch_size=32",
        "algo.eval_every=1",
    ],
    "sqil": SOFT_Q,
    "iq_learn": [*SOFT_Q, "algo.loss.num_value_samples=2"],
    "expert": [],
}


def tiny(algo: str, *extra: str, env: list[str] = ROVER) -> list[str]:
    """The overrides of a tiny ``algo`` run on ``env`` (RoverMaze-U, 40 steps, k = 2), then ``extra``.

    Examples:
        >>> tiny("bc", "algo.epochs=2")[:4], "algo.epochs=2" in tiny("bc", "algo.epochs=2"), "algo.epochs=3" in tiny("bc")
        (['env=rovermaze_u', 'env.horizon=40', 'window.k=2', 'algo=bc'], True, True)
    """
    return merged([*env, f"algo={algo}", *QUICK, *ALGO[algo], *extra])


def merged(overrides: list[str]) -> list[str]:
    """``overrides`` with each key once, at its first place, with its last value (what Hydra
    does with a key given twice, which the command line refuses).

    Examples:
        >>> merged(["a=1", "b=2", "a=3"])
        ['a=3', 'b=2']
    """
    by_key: dict[str, str] = {}
    for override in overrides:
        by_key[override.split("=", 1)[0].lstrip("+~")] = override
    return list(by_key.values())

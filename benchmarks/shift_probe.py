"""How a trained maze policy fares when P(U) moves, and how much it leans on the compass W.

Evaluates each run's selected policy (``checkpoints/best.pt``, deterministic actions; the
expert for an ``expert`` run) on the same episodes (same seed) under six conditions and
prints one table row per run, success % ± its binomial standard error:

* ``rotation train`` / ``rotation deploy``: the default shift (the compass turned by
  ``strength * pi`` when deployed), what the run's own records measured;
* ``prior train`` / ``prior deploy``: ``env.shift=prior``, the wind's distribution P(U)
  moved at deployment (:class:`~torchrl_causal.envs.base.PriorShift`), W diverted towards the
  wind by the strength in both regimes;
* ``prior train, W marg.`` / ``prior deploy, W marg.``: the same, with every reading of W
  replaced by an independent draw from W's training-regime marginal (the readings of the
  ``prior train`` episodes, pooled over their steps): what the policy
  does with no information in W. A policy that does not read W (a causal row) scores the same
  with and without it; the gap of a non-causal row is W's share in its decisions.

A policy trained in the rotation regime (every shipped policy) meets the prior shift's wind
for the first time here: its ``prior train`` column is not its training regime. Runs trained
with ``env.shift=prior`` read it as their training regime.

    OMP_NUM_THREADS=1 python benchmarks/shift_probe.py results/policies/antmaze_medium/h1000-cs1.0-k10/{c_sqil,sqil}/seed0 --episodes 40

``--horizon`` truncates episodes earlier than the run's horizon (smoke runs only: the
success rates then count fewer steps).
"""

from __future__ import annotations

import copy
from typing import Any

import torch
from omegaconf import DictConfig
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, Transform, TransformedEnv

from torchrl_causal.cli.arguments import OneLineParser, count, non_negative
from torchrl_causal.evaluation import Evaluator
from torchrl_causal.evaluation.metrics import EvaluationResult
from torchrl_causal.lifecycle import open_run

#: (column, env.shift, regime, W replaced by its training marginal)
CONDITIONS: tuple[tuple[str, str, str, bool], ...] = (
    ("rotation train", "rotation", "train", False),
    ("rotation deploy", "rotation", "deploy", False),
    ("prior train", "prior", "train", False),
    ("prior deploy", "prior", "deploy", False),
    ("prior train, W marg.", "prior", "train", True),
    ("prior deploy, W marg.", "prior", "deploy", True),
)


class RecordW(Transform):
    """Keeps the base env's ``"W"`` readings of the steps that do not end an episode (a
    finished episode's rows, which a batched evaluation carries along, are left out)."""

    def __init__(self) -> None:
        super().__init__(in_keys=["W"], out_keys=["W"])
        self.readings: list[torch.Tensor] = []

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        live = ~next_tensordict.get("done").reshape(-1)
        self.readings.append(next_tensordict.get("W").reshape(-1, 2)[live].clone())
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return tensordict_reset

    def pool(self) -> torch.Tensor:
        return torch.cat(self.readings)


class MarginalW(Transform):
    """Replaces the base env's ``"W"`` (at reset and every step) by independent draws from
    ``pool`` (``(n, 2)`` readings), so that W carries nothing about the state or the wind."""

    def __init__(self, pool: torch.Tensor, seed: int) -> None:
        super().__init__(in_keys=["W"], out_keys=["W"])
        self.pool = pool
        self.generator = torch.Generator().manual_seed(seed)

    def _draw(self, tensordict: TensorDictBase) -> TensorDictBase:
        w = tensordict.get("W")
        index = torch.randint(self.pool.shape[0], w.shape[:-1], generator=self.generator)
        return tensordict.set("W", self.pool[index].to(w.dtype))

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._draw(next_tensordict)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._draw(tensordict_reset)


class ProbeEvaluator(Evaluator):
    """An :class:`Evaluator` whose envs pass the base env's W through ``transform`` (a
    :class:`RecordW` or a :class:`MarginalW`) before the window reads it."""

    def __init__(self, cfg: DictConfig, window: Any, transform: Transform | None, **kwargs: Any) -> None:
        super().__init__(cfg, window, **kwargs)
        self.transform = transform

    def make_env(self, regime: str, batch_size: int, seed: int) -> EnvBase:
        env = super().make_env(regime, batch_size, seed)
        if self.transform is not None:
            if not isinstance(env, TransformedEnv):  # the expert's raw env
                env = TransformedEnv(env)
            env.insert_transform(0, self.transform)
        return env


def _with_shift(cfg: DictConfig, shift: str, horizon: int | None) -> DictConfig:
    cfg = copy.deepcopy(cfg)
    cfg.env.shift = None if shift == "rotation" else shift
    if horizon is not None:
        cfg.env.horizon = horizon
    return cfg


def probe(run_dir: str, episodes: int, seed: int, num_envs: int, horizon: int | None) -> dict[str, EvaluationResult]:
    """Each of :data:`CONDITIONS`' evaluations of the run's selected policy, in order; the
    ``prior train`` evaluation records the readings that make W's training marginal."""
    _, evaluator, policy = open_run(run_dir)
    results: dict[str, EvaluationResult] = {}
    recorder = RecordW()
    for column, shift, regime, marginal in CONDITIONS:
        transform: Transform | None = None
        if marginal:
            transform = MarginalW(recorder.pool(), seed)
        elif (shift, regime) == ("prior", "train"):
            transform = recorder
        probe_evaluator = ProbeEvaluator(_with_shift(evaluator.cfg, shift, horizon), evaluator.window, transform, device=evaluator.device)
        results[column] = probe_evaluator.evaluate(policy, regime, episodes, seed, num_envs=num_envs)
    return results


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories (with checkpoints/best.pt, or an expert run)")
    parser.add_argument("--episodes", type=count, default=40)
    parser.add_argument("--seed", type=non_negative, default=50_000, help="evaluation seed (the same episodes in every column)")
    parser.add_argument("--num-envs", type=count, default=20, help="episodes simulated at once")
    parser.add_argument("--horizon", type=count, default=None, help="truncate episodes here (smoke runs; default: the run's)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    columns = [column for column, *_ in CONDITIONS]
    print(f"success % ± s.e. over {args.episodes} episodes per column (seed {args.seed})\n")
    print("| run | " + " | ".join(columns) + " |")
    print("|---|" + "---:|" * len(columns))
    for run in args.runs:
        results = probe(run, args.episodes, args.seed, min(args.num_envs, args.episodes), args.horizon)
        cells = [f"{100 * results[c].success_rate:.1f} ± {100 * results[c].success_se:.1f}" for c in columns]
        print(f"| {run} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()

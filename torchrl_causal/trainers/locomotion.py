"""The ant expert's locomotion skill: SAC in open ground, in the wind, with TorchRL parts.

OGBench generated its AntMaze datasets with a goal-direction locomotion policy steered by a
planner; this trains that policy the way OGBench did (SAC, 2 x 256 MLPs, batch 256,
gamma 0.99, tau 0.005, 10k uniformly random steps, one gradient step per env step, ~400k env
steps) on :class:`~torchrl_causal.envs.ant.AntLocomotionEnv`, with TorchRL's
:class:`~torchrl.objectives.SACLoss`, :class:`~torchrl.collectors.Collector` and
:class:`~torchrl.data.TensorDictReplayBuffer`.

Runs resume: every ``checkpoint_minutes`` the networks, optimisers, counters and RNG states
go to ``<run_dir>/checkpoint.pt`` and the replay buffer to ``<run_dir>/buffer`` (both
atomically); a restarted run continues from them (in-flight episodes restart). The best
evaluation's policy body is exported to ``--output`` (by default the weights shipped in
the package, :data:`~torchrl_causal.envs.ant.LOCOMOTION_WEIGHTS`)::

    python -m torchrl_causal.trainers.locomotion --run-dir runs/ant_locomotion --steps 400000
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate
from torchrl.record.loggers.csv import CSVLogger

from torchrl_causal.envs.ant import (
    LOCOMOTION_OBSERVATION_DIM,
    LOCOMOTION_WEIGHTS,
    AntLocomotionEnv,
    make_locomotion_network,
)
from torchrl_causal.trainers.run_directory import atomic_save, load_checkpoint

__all__ = ["LocomotionConfig", "evaluate_locomotion", "make_locomotion_actor", "train_locomotion"]

_CHECKPOINT = "checkpoint.pt"
_BUFFER = "buffer"
_CONFIG = "locomotion_config.json"
#: what SACLoss reads; the collector's other entries (loc, scale, xy...) stay out of the buffer.
_TRANSITION_KEYS = ("observation", "action", ("next", "observation"), ("next", "reward"), ("next", "done"),
                    ("next", "terminated"))


@dataclass(frozen=True)
class LocomotionConfig:
    """Budget and hyperparameters of the locomotion SAC run (OGBench's by default)."""

    total_steps: int = 400_000
    buffer_size: int = 400_000
    random_steps: int = 10_000
    num_envs: int = 4
    frames_per_batch: int = 200
    updates_per_step: float = 1.0
    batch_size: int = 256
    gamma: float = 0.99
    tau: float = 0.005
    lr: float = 3e-4
    hidden: int = 256
    eval_every: int = 20_000
    eval_envs: int = 8
    eval_steps: int = 300
    checkpoint_minutes: float = 5.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("total_steps", "buffer_size", "num_envs", "frames_per_batch", "batch_size", "hidden", "eval_every",
                     "eval_envs", "eval_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.frames_per_batch % self.num_envs:
            raise ValueError(f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs ({self.num_envs})")
        if not 0 < self.tau <= 1 or not 0 < self.gamma < 1:
            raise ValueError(f"need 0 < tau <= 1 and 0 < gamma < 1, got tau={self.tau}, gamma={self.gamma}")


def make_locomotion_actor(body: nn.Module | None = None) -> ProbabilisticActor:
    """The tanh-Gaussian SAC actor around :func:`~torchrl_causal.envs.ant.make_locomotion_network`.

    Its deterministic action is ``tanh`` of the body's first 8 outputs, which is what
    :class:`~torchrl_causal.envs.AntMazeExpert` computes from the exported body.

    Examples:
        >>> from tensordict import TensorDict
        >>> actor = make_locomotion_actor()
        >>> actor(TensorDict(observation=torch.zeros(2, 29), batch_size=[2]))["action"].shape
        torch.Size([2, 8])
    """
    body = make_locomotion_network() if body is None else body
    module = TensorDictModule(nn.Sequential(body, NormalParamExtractor()), in_keys=["observation"],
                              out_keys=["loc", "scale"])
    return ProbabilisticActor(module, in_keys=["loc", "scale"], out_keys=["action"], distribution_class=TanhNormal,
                              distribution_kwargs={"low": -1.0, "high": 1.0}, return_log_prob=False)


def _make_critic(hidden: int) -> ValueOperator:
    # TorchRL's MLP concatenates its (observation, action) inputs.
    network = MLP(in_features=LOCOMOTION_OBSERVATION_DIM + 8, out_features=1, num_cells=[hidden, hidden],
                  activation_class=nn.ReLU)
    return ValueOperator(network, in_keys=["observation", "action"])


@torch.no_grad()
def evaluate_locomotion(body: nn.Module, *, envs: int = 8, steps: int = 300, seed: int = 12345) -> dict[str, float]:
    """Deterministic rollouts of ``body``: mean speed (m/s) along the commanded direction, and falls.

    The direction is redrawn every 100 steps, so ``steps=300`` covers three directions per env.
    """
    env = AntLocomotionEnv(batch_size=envs, horizon=steps, seed=seed)
    actor = make_locomotion_actor(body)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = env.rollout(steps, actor, break_when_any_done=False)
    return {"speed": rollout["next", "reward"].mean().item(),
            "fall_rate": rollout["next", "terminated"].any(-2).float().mean().item()}


class _Progress:
    """A tqdm bar on a terminal, else a plain line every ``every`` steps (logs stay readable)."""

    def __init__(self, total: int, initial: int, every: int = 10_000) -> None:
        self.every, self.last = every, initial
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=initial, unit="step", desc="ant locomotion")
        self.total = total

    def update(self, done: int, **scalars: float) -> None:
        text = " ".join(f"{k}={v:.3g}" for k, v in scalars.items())
        if self.bar is not None:
            self.bar.update(done - self.bar.n)
            self.bar.set_postfix_str(text)
        elif done - self.last >= self.every or done >= self.total:
            self.last = done
            print(f"[ant locomotion] {done}/{self.total} steps {text}", flush=True)


def train_locomotion(run_dir: str | Path, config: LocomotionConfig = LocomotionConfig(), *,
                     output: str | Path | None = LOCOMOTION_WEIGHTS) -> dict[str, Any]:
    """Trains (or resumes) the locomotion policy in ``run_dir``; exports the best body to ``output``.

    Returns the final record: steps, updates, best evaluation and the export path. A run
    directory made with another config is refused (the changed fields are named).
    """
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    config_path = run_dir / _CONFIG
    if config_path.exists():
        saved = json.loads(config_path.read_text())
        # The budget may grow (a finished run then continues); everything else fixes the result.
        changed = sorted(k for k, v in asdict(config).items() if k != "total_steps" and saved.get(k) != v)
        if changed:
            raise ValueError(f"{run_dir} was trained with another config (changed: {changed}); "
                             "use a new --run-dir or the same settings")
    config_path.write_text(json.dumps(asdict(config), indent=2))
    torch.manual_seed(config.seed)

    actor = make_locomotion_actor(make_locomotion_network(config.hidden))
    loss = SACLoss(actor, _make_critic(config.hidden), num_qvalue_nets=2, loss_function="l2",
                   action_spec=AntLocomotionEnv(batch_size=1).action_spec[0])
    loss.make_value_estimator(gamma=config.gamma)
    target_updater = SoftUpdate(loss, tau=config.tau)
    optimizers = {
        "actor": torch.optim.Adam(loss.actor_network_params.flatten_keys().values(), lr=config.lr),
        "critic": torch.optim.Adam(loss.qvalue_network_params.flatten_keys().values(), lr=config.lr),
        "alpha": torch.optim.Adam([loss.log_alpha], lr=config.lr),
    }
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(config.buffer_size), batch_size=config.batch_size)
    counters = {"steps": 0, "updates": 0, "update_debt": 0.0, "best_speed": -math.inf, "collect_seed": config.seed}

    checkpoint = run_dir / _CHECKPOINT
    if checkpoint.exists():
        state = load_checkpoint(checkpoint)
        loss.load_state_dict(state["loss"])
        for name, optimizer in optimizers.items():
            optimizer.load_state_dict(state["optimizers"][name])
        counters.update(state["counters"])
        torch.set_rng_state(state["torch_rng"])
        buffer.loads(run_dir / _BUFFER)
        print(f"[ant locomotion] resumed at {counters['steps']} steps from {checkpoint}", flush=True)

    def save() -> None:
        tmp = run_dir / (_BUFFER + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        buffer.dumps(tmp)
        old = run_dir / (_BUFFER + ".old")
        shutil.rmtree(old, ignore_errors=True)
        if (run_dir / _BUFFER).exists():
            (run_dir / _BUFFER).rename(old)
        tmp.rename(run_dir / _BUFFER)
        shutil.rmtree(old, ignore_errors=True)
        atomic_save({"progress": counters["steps"], "loss": loss.state_dict(), "optimizers": {k: o.state_dict() for k, o in optimizers.items()},
                     "counters": dict(counters), "torch_rng": torch.get_rng_state()}, checkpoint)

    logger = CSVLogger(exp_name="locomotion", log_dir=str(run_dir / "logs"))
    remaining = config.total_steps - counters["steps"]
    progress = _Progress(config.total_steps, counters["steps"])
    if remaining > 0:
        # A resumed run draws fresh episodes from a new seed (env state is not checkpointed).
        counters["collect_seed"] += 1
        env = AntLocomotionEnv(batch_size=config.num_envs, seed=counters["collect_seed"])
        random_left = max(0, config.random_steps - counters["steps"])
        collector = Collector(env, actor, frames_per_batch=config.frames_per_batch,
                              total_frames=math.ceil(remaining / config.frames_per_batch) * config.frames_per_batch,
                              init_random_frames=math.ceil(random_left / config.frames_per_batch) * config.frames_per_batch,
                              device="cpu", auto_register_policy_transforms=False)
        last_save = time.monotonic()
        for batch in collector:
            buffer.extend(batch.reshape(-1).select(*_TRANSITION_KEYS))
            counters["steps"] += batch.numel()
            metrics: dict[str, float] = {"train_reward": batch["next", "reward"].mean().item()}
            if counters["steps"] > config.random_steps:
                counters["update_debt"] += config.updates_per_step * batch.numel()
                while counters["update_debt"] >= 1:
                    losses = loss(buffer.sample())
                    total = losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]
                    for optimizer in optimizers.values():
                        optimizer.zero_grad(set_to_none=True)
                    total.backward()
                    for optimizer in optimizers.values():
                        optimizer.step()
                    target_updater.step()
                    counters["updates"] += 1
                    counters["update_debt"] -= 1
                metrics.update(loss_qvalue=losses["loss_qvalue"].item(), alpha=losses["alpha"].item(),
                               entropy=losses["entropy"].item())
            collector.update_policy_weights_()
            steps = counters["steps"]
            if steps % config.eval_every < config.frames_per_batch or steps >= config.total_steps:
                body = actor.module[0].module[0]
                result = evaluate_locomotion(body, envs=config.eval_envs, steps=config.eval_steps)
                metrics.update(eval_speed=result["speed"], eval_fall_rate=result["fall_rate"])
                if result["speed"] > counters["best_speed"]:
                    counters["best_speed"] = result["speed"]
                    atomic_save(body.state_dict(), run_dir / "best_body.pt")
                save()
                last_save = time.monotonic()
            elif time.monotonic() - last_save > 60 * config.checkpoint_minutes:
                save()
                last_save = time.monotonic()
            for name, value in metrics.items():
                logger.log_scalar(name, value, step=steps)
            progress.update(steps, **{k: v for k, v in metrics.items() if k in ("train_reward", "eval_speed", "alpha")})
            if steps >= config.total_steps:
                break
        collector.shutdown()
        save()
    record = {"steps": counters["steps"], "updates": counters["updates"], "best_eval_speed": counters["best_speed"]}
    if output is not None and (run_dir / "best_body.pt").exists():
        output = Path(output)
        output.parent.mkdir(parents=True, exist_ok=True)
        atomic_save(torch.load(run_dir / "best_body.pt", weights_only=True), output)
        record["exported"] = str(output)
    (run_dir / "result.json").write_text(json.dumps(record, indent=2))
    return record


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run-dir", default="runs/ant_locomotion", help="checkpoints, buffer and logs (resumed)")
    parser.add_argument("--steps", type=int, default=LocomotionConfig.total_steps, help="total env steps")
    parser.add_argument("--utd", type=float, default=LocomotionConfig.updates_per_step,
                        help="gradient steps per env step (OGBench: 1)")
    parser.add_argument("--seed", type=int, default=LocomotionConfig.seed)
    parser.add_argument("--output", default=str(LOCOMOTION_WEIGHTS), help="where the best policy body is exported")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (one is fastest on small CPUs)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    record = train_locomotion(args.run_dir, LocomotionConfig(total_steps=args.steps, updates_per_step=args.utd,
                                                                 seed=args.seed),
                              output=args.output)
    print(json.dumps(record))


if __name__ == "__main__":
    main()

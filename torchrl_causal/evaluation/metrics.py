"""Batched episode evaluation and the paper's metrics (Section 4, Appendix F).

:func:`evaluate_policy` runs complete episodes of a policy in a batched env and returns an
:class:`EvaluationResult`: success rate with its standard error, raw ``E[Y]`` (the mean
episode return) with its standard deviation, and the mean/std length of the *successful*
episodes (Appendix F's episode-length table). Per-episode values are kept so that results
of several seeds pool exactly (:meth:`EvaluationResult.pool`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from torchrl_causal.envs.base import STEP_MASK_KEY
from torchrl_causal.errors import InvalidValueError
from torchrl_causal.progress import progress as progress_reporter

__all__ = ["SUMMARY_COLUMNS", "EpisodeObserver", "EvaluationResult", "evaluate_policy", "metrics_summary"]

Policy = Callable[[TensorDictBase], TensorDictBase]

#: Decimals kept of a recorded trajectory position: plots need far less, and full floats
#: were three quarters of an evaluation record's size.
TRAJECTORY_DECIMALS = 4

#: An evaluation's flat metrics, in the results CSV's order (``seeds``: how many training
#: seeds it pools).
SUMMARY_COLUMNS: tuple[str, ...] = (
    "regime",
    "success_rate",
    "success_se",
    "return_mean",
    "return_std",
    "ep_len_mean",
    "ep_len_std",
    "n_episodes",
    "seeds",
)


def metrics_summary(result: Any) -> dict[str, float | int | str]:
    """The :data:`SUMMARY_COLUMNS` of ``result`` (an :class:`EvaluationResult`, or a table row
    read back with the same metrics), ``seeds`` from its ``seed_count``: every summary the
    package prints or writes is this one.

    Examples:
        >>> metrics_summary(EvaluationResult("deploy", [True, False], [-1.0, -9.0], [4, 9], seeds=[0, 0]))["seeds"]
        1
    """
    return {column: getattr(result, "seed_count" if column == "seeds" else column) for column in SUMMARY_COLUMNS}


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    if not values:
        return math.nan, math.nan
    tensor = torch.tensor(values, dtype=torch.float64)
    return tensor.mean().item(), tensor.std(unbiased=False).item()


class EpisodeObserver(Protocol):
    """Watches the episodes of :func:`evaluate_policy` as they run (a video recorder), and
    must change nothing in them: it may read the env's state (render it), never step,
    reset or seed it, nor draw from its random generator.

    Calls, for every round of ``env.batch_size`` parallel episodes: :meth:`on_reset` after
    the reset, :meth:`on_step` after every step, :meth:`on_round_end` once all are done.
    """

    def on_reset(self, env: EnvBase, episodes: range) -> None:
        """A round started: batch row ``i`` plays episode ``episodes[i]`` (the rows past
        ``len(episodes)`` run too, but are not counted)."""

    def on_step(self, env: EnvBase, stepped: torch.Tensor, ended: torch.Tensor) -> None:
        """The rows in ``stepped`` (a flat bool mask over the batch) took a step; ``ended``
        marks those whose episode ended with it (done, or at ``max_steps``)."""

    def on_round_end(self) -> None:
        """Every counted episode of the round has ended."""


@dataclass(frozen=True)
class EvaluationResult:
    """Per-episode outcomes of an evaluation and the metrics derived from them.

    Attributes:
        regime: ``"train"`` or ``"deploy"``.
        successes: one bool per episode.
        returns: one return (the latent reward ``Y`` summed over the episode) per episode.
        lengths: one length (steps until done) per episode.
        seeds: training seeds the episodes come from (several after :meth:`pool`).
        trajectories: a few episodes' positions, each a list of ``[x, y]`` (for plots;
            :meth:`to_dict` keeps :data:`TRAJECTORY_DECIMALS` decimals of each).

    Examples:
        >>> r = EvaluationResult("deploy", successes=[True, False, True, True],
        ...                      returns=[-10.0, -100.0, -20.0, -30.0], lengths=[10, 100, 20, 30])
        >>> r.success_rate, round(r.success_se, 4), r.return_mean, r.ep_len_mean
        (0.75, 0.2165, -40.0, 20.0)
        >>> EvaluationResult.from_dict(r.to_dict()) == r
        True
    """

    regime: str
    successes: Sequence[bool]
    returns: Sequence[float]
    lengths: Sequence[int]
    seeds: Sequence[int] = (0,)
    trajectories: Sequence[Sequence[Sequence[float]]] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        sizes = {len(self.successes), len(self.returns), len(self.lengths)}
        if len(sizes) != 1:
            raise InvalidValueError(
                f"successes, returns and lengths must have one entry per episode, got sizes "
                f"{len(self.successes)}, {len(self.returns)}, {len(self.lengths)}"
            )
        object.__setattr__(self, "successes", tuple(bool(s) for s in self.successes))
        object.__setattr__(self, "returns", tuple(float(r) for r in self.returns))
        object.__setattr__(self, "lengths", tuple(int(n) for n in self.lengths))
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))

    @property
    def n_episodes(self) -> int:
        return len(self.successes)

    @property
    def success_rate(self) -> float:
        return sum(self.successes) / self.n_episodes if self.n_episodes else math.nan

    @property
    def success_se(self) -> float:
        """Binomial standard error ``sqrt(p (1 - p) / n)``."""
        p = self.success_rate
        return math.sqrt(p * (1.0 - p) / self.n_episodes) if self.n_episodes else math.nan

    @property
    def return_mean(self) -> float:
        return _mean_std(self.returns)[0]

    @property
    def return_std(self) -> float:
        return _mean_std(self.returns)[1]

    @property
    def successful_lengths(self) -> tuple[int, ...]:
        return tuple(n for n, s in zip(self.lengths, self.successes) if s)

    @property
    def ep_len_mean(self) -> float:
        """Mean length of the successful episodes (NaN when none succeeded)."""
        return _mean_std(self.successful_lengths)[0]

    @property
    def ep_len_std(self) -> float:
        return _mean_std(self.successful_lengths)[1]

    @property
    def seed_count(self) -> int:
        """How many training seeds this result pools."""
        return len(set(self.seeds))

    def summary(self) -> dict[str, float | int | str]:
        """The metrics as a flat mapping (the columns of the results CSV: :func:`metrics_summary`)."""
        return metrics_summary(self)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["trajectories"] = [[[round(float(x), TRAJECTORY_DECIMALS) for x in point] for point in path] for path in self.trajectories]
        data["summary"] = self.summary()
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EvaluationResult:
        missing = {"regime", "successes", "returns", "lengths"} - set(data)
        if missing:
            raise InvalidValueError(f"evaluation record lacks {sorted(missing)}")
        return cls(
            regime=data["regime"],
            successes=data["successes"],
            returns=data["returns"],
            lengths=data["lengths"],
            seeds=data.get("seeds", (0,)),
            trajectories=data.get("trajectories", ()),
        )

    @classmethod
    def pool(cls, results: Sequence[EvaluationResult]) -> EvaluationResult:
        """Concatenates the episodes of several evaluations (e.g. one per seed).

        Examples:
            >>> a = EvaluationResult("deploy", [True], [-1.0], [1], seeds=[0])
            >>> b = EvaluationResult("deploy", [False], [-9.0], [9], seeds=[1])
            >>> pooled = EvaluationResult.pool([a, b])
            >>> pooled.success_rate, pooled.return_mean, pooled.seeds
            (0.5, -5.0, (0, 1))
        """
        if not results:
            raise InvalidValueError("cannot pool an empty list of evaluation results")
        regimes = {r.regime for r in results}
        if len(regimes) != 1:
            raise InvalidValueError(f"cannot pool results of different regimes {sorted(regimes)}")
        return cls(
            regime=results[0].regime,
            successes=[s for r in results for s in r.successes],
            returns=[x for r in results for x in r.returns],
            lengths=[n for r in results for n in r.lengths],
            seeds=[s for r in results for s in r.seeds],
            trajectories=[t for r in results for t in r.trajectories],
        )


@torch.no_grad()
def evaluate_policy(
    env: EnvBase,
    policy: Policy,
    *,
    episodes: int,
    max_steps: int,
    regime: str,
    seeds: Sequence[int] = (0,),
    position_key: str | None = None,
    trajectories: int = 0,
    progress: bool = False,
    skip_finished: bool = True,
    observer: EpisodeObserver | None = None,
) -> EvaluationResult:
    """Runs ``episodes`` complete episodes of ``policy`` in the batched ``env``.

    The env is reset in rounds of ``env.batch_size`` parallel episodes; each round keeps
    the first episode of every sub-env (stepping stops once all of them are done), so every
    episode is counted whatever its length. Actions are the policy's deterministic mode.

    An env whose episode ended is not simulated for the rest of its round: every step
    carries TorchRL's partial-step mask (``"_step"``, :data:`~torchrl_causal.envs.base.STEP_MASK_KEY`)
    of the episodes still running, which a :class:`~torchrl_causal.envs.ConfoundedEnv`
    honours with the outcomes of a full step in the rows it steps (it draws its random
    numbers for the whole batch). On the MuJoCo mazes, where failed episodes run to the
    horizon, this skips about half the physics; the per-episode results are bit-identical
    to stepping every env (``skip_finished=False``, the former loop, kept as the
    reference). The policy still acts on the whole batch: on a CPU, a linear layer's output
    rows on a subset of the batch differ from the same rows on the whole batch in the last
    bits (the matmul kernel depends on the row count; measured on the shipped AntMaze
    actor), and the policy is a small part of a step next to the physics.

    Args:
        env: a batched env with a 1-D batch (possibly a ``TransformedEnv``), seeded by the
            caller.
        policy: reads the env's (transformed) observation, writes ``"action"``.
        episodes: number of episodes to run.
        max_steps: an upper bound on the episode length (the env's horizon).
        regime: recorded in the result (the env decides what the regime does).
        seeds: recorded in the result.
        position_key: observation key of the 2-D position, recorded for the first
            ``trajectories`` episodes (``None`` records nothing).
        progress: report progress over episodes (a bar on a terminal, else log lines).
        skip_finished: stop stepping the envs whose episode ended (``False``: step every
            env until the round's last episode ends).
        observer: told of every reset and step (:class:`EpisodeObserver`; e.g.
            :class:`~torchrl_causal.evaluation.video.EpisodeVideos`); the episodes and the
            result are the same with or without it.

    Examples:
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> env = RouteChoiceEnv(batch_size=(64,), regime="train", seed=0)
        >>> def expert(td):
        ...     return td.set("action", (td["Z"].long() ^ td["latent", "O"].long()).float())
        >>> result = evaluate_policy(env, expert, episodes=2000, max_steps=1, regime="train")
        >>> result.n_episodes, abs(result.success_rate - 0.75) < 0.05
        (2000, True)
    """
    if episodes < 1:
        raise InvalidValueError(f"episodes must be >= 1, got {episodes}")
    if len(env.batch_size) != 1:
        raise InvalidValueError(f"evaluate_policy needs an env with a 1-D batch, got batch_size {tuple(env.batch_size)}")
    width = env.batch_size[0]
    successes: list[bool] = []
    returns: list[float] = []
    lengths: list[int] = []
    paths: list[list[list[float]]] = []
    bar = progress_reporter(episodes, f"eval[{regime}]", "episodes", enabled=progress, leave=False)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        while len(successes) < episodes:
            td = env.reset()
            if observer is not None:
                observer.on_reset(env, range(len(successes), min(len(successes) + width, episodes)))
            alive = torch.ones(width, dtype=torch.bool)
            episode_return = torch.zeros(width, dtype=torch.float64)
            length = torch.zeros(width, dtype=torch.int64)
            success = torch.zeros(width, dtype=torch.bool)
            keep = min(trajectories - len(paths), width) if position_key is not None else 0
            track = [[td[position_key][i, :2].tolist()] for i in range(keep)]
            for step in range(1, max_steps + 1):
                td = policy(td)
                if skip_finished:
                    td.set(STEP_MASK_KEY, alive.clone())
                td = env.step(td)
                nxt = td["next"]
                episode_return += torch.where(alive, nxt["reward"].reshape(width).double(), 0.0)
                length += alive.long()
                success |= alive & nxt["success"].reshape(width)
                for i in range(keep):
                    if alive[i]:
                        track[i].append(nxt[position_key][i, :2].tolist())
                done = nxt["done"].reshape(width)
                if observer is not None:
                    observer.on_step(env, alive.clone(), alive & (done | (step == max_steps)))
                alive &= ~done
                if not alive.any():
                    break
                td = step_mdp(td, keep_other=True)
            if observer is not None:
                observer.on_round_end()
            take = min(width, episodes - len(successes))
            successes += success[:take].tolist()
            returns += episode_return[:take].tolist()
            lengths += length[:take].tolist()
            paths += track
            bar.update(take)
    bar.close()
    return EvaluationResult(regime, successes, returns, lengths, seeds=seeds, trajectories=paths)

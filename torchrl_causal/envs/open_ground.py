"""Open-ground directional locomotion: the task the maze experts' walking skills are trained on.

:class:`DirectionalLocomotionEnv` is what the ant's and the humanoid's skill envs share: a batch
of MuJoCo simulations on open ground, a commanded unit ground-plane direction redrawn every
``direction_period`` steps (a fixed period, or one drawn uniformly from a range at each redraw),
the maze suite's :class:`~torchrl_causal.envs.GustProcess` pushing the torso, termination when
the agent falls, truncation at ``horizon``. Subclasses name the model, the start state, the
observation and the reward.

Every step also writes ``"speed"``, the torso's ground-plane velocity along the command (m/s),
and ``"xy"``, the torso position, for evaluation (neither is in the observation).
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Sequence

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Bounded, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_causal.envs.base import GustProcess
from torchrl_causal.envs.mujoco_maze import BatchedSimulation
from torchrl_causal.errors import InvalidValueError

__all__ = ["DirectionalLocomotionEnv", "root_heading"]


def root_heading(qpos: np.ndarray) -> np.ndarray:
    """The yaw (radians) of each root body's x-axis on the ground, from a free joint's ``qpos[:, 3:7]`` (w, x, y, z, any norm).

    Examples:
        >>> qpos = np.zeros((2, 7))
        >>> qpos[:, 3:7] = [[1, 0, 0, 0], [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]]  # facing +x, then turned 90 deg
        >>> root_heading(qpos).round(6).tolist()
        [0.0, 1.570796]
    """
    w, x, y, z = qpos[:, 3], qpos[:, 4], qpos[:, 5], qpos[:, 6]
    # w^2 + x^2 - y^2 - z^2 rather than 1 - 2 (y^2 + z^2): exact for a quaternion MuJoCo has not
    # normalised yet (a reset's noise leaves it off unit length).
    return np.arctan2(2 * (w * z + x * y), w * w + x * x - y * y - z * z)


class DirectionalLocomotionEnv(EnvBase):
    """Base of the skill envs: walk along a commanded direction in open ground, in the gusts.

    ``"observation"`` (``observation_dim``) is the subclass's; a ``"direction"`` entry in the
    reset tensordict fixes the first commanded directions instead of drawing them.

    Args:
        simulation: the batched simulations (one dimension of batch).
        observation_dim: width of ``"observation"``.
        horizon: steps before truncation.
        direction_period: steps between direction redraws, or ``(low, high)`` to draw each
            period uniformly from ``low..high`` (inclusive).
        gust_process: the pushes (the maze suite's by default; ``GustProcess(probability=0)`` for calm).
        seed: seed of the env's generator.
        command_spread: each command is drawn uniformly within this angle (radians) of the root
            body's heading (its x-axis on the ground) at the draw; ``pi`` (the default) is uniform
            over the circle, whatever the heading. A skill that cannot see its heading (OGBench's
            humanoid observation has no yaw) earns nothing on average by walking straight under
            uniform commands, only by walking and steering; ``0`` (always straight ahead) teaches
            the walk first, a curriculum's first stage.
    """

    def __init__(
        self,
        simulation: BatchedSimulation,
        *,
        observation_dim: int,
        horizon: int,
        direction_period: int | tuple[int, int],
        gust_process: GustProcess | None,
        seed: int | None,
        command_spread: float = math.pi,
    ) -> None:
        n = simulation.num_envs
        if not 0 <= command_spread <= math.pi:
            raise InvalidValueError(f"command_spread must lie in [0, pi], got {command_spread}")
        self.command_spread = float(command_spread)
        low, high = (direction_period, direction_period) if isinstance(direction_period, int) else direction_period
        if horizon < 1 or not 1 <= low <= high:
            raise InvalidValueError(f"need horizon >= 1 and 1 <= direction_period, got {horizon}, {direction_period!r}")
        super().__init__(batch_size=torch.Size([n]), device="cpu")
        self.simulation = simulation
        self.horizon, self.direction_period = horizon, direction_period
        self._period_range = (low, high)
        self.gust_process = GustProcess() if gust_process is None else gust_process
        self.rng = torch.Generator()
        self._set_seed(seed)
        self._direction = torch.zeros(n, 2)
        self._gust = torch.zeros(n, 2)
        self._steps = torch.zeros(n, 1, dtype=torch.int64)
        self._next_redraw = torch.zeros(n, 1, dtype=torch.int64)
        self.observation_spec = Composite(
            observation=Unbounded(shape=(n, observation_dim)),
            direction=Unbounded(shape=(n, 2)),
            xy=Unbounded(shape=(n, 2)),
            speed=Unbounded(shape=(n, 1)),
            shape=(n,),
        )
        self.action_spec = Bounded(-1.0, 1.0, shape=(n, simulation.model.nu))
        self.reward_spec = Unbounded(shape=(n, 1))
        flag = Binary(n=1, shape=(n, 1), dtype=torch.bool)
        self.full_done_spec = Composite(done=flag.clone(), terminated=flag.clone(), truncated=flag.clone(), shape=(n,))

    @staticmethod
    def batch_count(batch_size: int | Sequence[int]) -> int:
        """The number of simulations of a one-dimensional ``batch_size``; anything else is refused."""
        shape = (batch_size,) if isinstance(batch_size, int) else tuple(batch_size)
        if len(shape) != 1 or shape[0] < 1:
            raise InvalidValueError(f"batch_size must be one positive dimension, got {batch_size!r}")
        return shape[0]

    # -- subclass hooks ------------------------------------------------------------------

    @abstractmethod
    def _start_state(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``(qpos, qvel)`` of ``count`` fresh episodes, drawn from :attr:`rng`."""

    @abstractmethod
    def _read(self, qpos: np.ndarray) -> torch.Tensor:
        """The observation without the direction, ``(n, observation_dim - 2)``, from the simulations' state
        (``qpos`` is a fresh copy of their positions)."""

    @abstractmethod
    def _reward_and_fall(self, speed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(reward, fallen)``, both ``(n, 1)``, after a step with ground-plane ``speed`` along the command."""

    # -- EnvBase ---------------------------------------------------------------------------

    def _set_seed(self, seed: int | None) -> None:
        self.rng.manual_seed(int(torch.randint(0, 2**62, ()).item()) if seed is None else seed)

    def _draw_directions(self, count: int, qpos: np.ndarray) -> torch.Tensor:
        """``count`` unit commands for the simulations whose positions are ``qpos`` (``(count, nq)``)."""
        if self.command_spread >= math.pi:  # uniform: the heading is irrelevant (and the random stream as before)
            angle = 2 * math.pi * torch.rand(count, generator=self.rng)
        else:
            offset = self.command_spread * (2 * torch.rand(count, generator=self.rng) - 1)
            angle = torch.from_numpy(root_heading(qpos)).float() + offset
        return torch.stack((angle.cos(), angle.sin()), dim=-1)

    def _draw_periods(self, count: int) -> torch.Tensor:
        low, high = self._period_range
        if low == high:  # draws nothing, so a fixed period leaves the random stream alone
            return torch.full((count, 1), low, dtype=torch.int64)
        return torch.randint(low, high + 1, (count, 1), generator=self.rng)

    def _observe(self, qpos: np.ndarray, speed: torch.Tensor | None = None) -> TensorDict:
        return TensorDict(
            observation=torch.cat((self._read(qpos), self._direction), dim=-1),
            direction=self._direction.clone(),
            xy=torch.from_numpy(qpos[:, :2]).float(),
            speed=torch.zeros(self.batch_size[0], 1) if speed is None else speed,
            batch_size=self.batch_size,
        )

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        n = self.batch_size[0]
        mask = torch.ones(n, dtype=torch.bool)
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(n)
        indices = mask.nonzero().flatten()
        qpos = None
        if len(indices):
            count = len(indices)
            self.simulation.reset(indices.numpy(), *self._start_state(count))
            qpos = self.simulation.qpos()  # the fresh starts' positions: the commands and the observation read them
            given = None if tensordict is None else tensordict.get("direction", None)
            if given is None:
                self._direction[indices] = self._draw_directions(count, qpos[indices.numpy()])
            else:
                self._direction[indices] = given[indices].float()
            self._gust[indices] = self.gust_process.draw((count,), generator=self.rng)
            self._steps[indices] = 0
            self._next_redraw[indices] = self._draw_periods(count)
        return self._observe(self.simulation.qpos() if qpos is None else qpos)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        before = tensordict.get("xy")
        ctrl = tensordict.get("action").detach().clamp(-1.0, 1.0).numpy()
        self.simulation.step(ctrl, self._gust.numpy())
        qpos = self.simulation.qpos()
        velocity = (torch.from_numpy(qpos[:, :2]).float() - before) / self.simulation.control_dt
        speed = (velocity * self._direction).sum(-1, keepdim=True)
        reward, terminated = self._reward_and_fall(speed)
        self._steps += 1
        truncated = self._steps >= self.horizon
        redraw = (self._steps >= self._next_redraw).flatten()
        if redraw.any():
            count = int(redraw.sum())
            self._direction[redraw] = self._draw_directions(count, qpos[redraw.numpy()])
            self._next_redraw[redraw] = self._steps[redraw] + self._draw_periods(count)
        self._gust = self.gust_process.advance(self._gust, self._steps, generator=self.rng)
        out = self._observe(qpos, speed)
        out.update({"reward": reward, "terminated": terminated, "truncated": truncated, "done": terminated | truncated})
        return out

"""Scripted experts: TorchRL policies that see the latent state the imitator does not."""

from __future__ import annotations

import math

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_causal.envs.planner import MazePlanner
from torchrl_causal.envs.rover_maze import RoverMazeEnv, RoverParameters

__all__ = ["RouteChoiceExpert", "RoverExpert"]


class RoverExpert(TensorDictModuleBase):
    """Waypoint-following expert for :class:`~torchrl_causal.envs.RoverMazeEnv`.

    Reads the position ``"P"`` and the true heading ``("latent", "O")`` and writes
    ``"action"`` = (throttle, turn): it turns towards the :class:`MazePlanner` waypoint in
    proportion to the heading error (``turn_gain * error / turn_rate``, clipped) and
    throttles by the cosine of the error, never below ``min_throttle`` (so it always creeps
    forward while it turns, which keeps its heading visible in its displacement).

    Gaussian noise of ``noise_std`` is added to both action components (then clipped), as
    in DART: the demonstrations then show how the expert recovers from small deviations,
    which behaviour cloning needs to stay on track in closed loop. ``noise_std=0`` gives a
    deterministic expert. The smooth gain (rather than turning as fast as possible) keeps
    the action a gentle function of the heading, so an imitator that infers the heading
    approximately still acts nearly as the expert does.

    Args:
        env: the env to solve (its maze, goal and rover parameters are read once).
        min_throttle: smallest throttle, applied when facing away from the waypoint.
        margin: extra clearance (cells) beyond the rover's footprint for lines of sight.
        lookahead: path cells the planner may look ahead.
        turn_gain: fraction of the heading error corrected per step (before clipping).
        noise_std: standard deviation of the action noise.
        seed: seed of the noise generator (``None`` draws one from torch's global RNG).

    Examples:
        >>> env = RoverMazeEnv(maze="u", batch_size=(16,), seed=0)
        >>> td = env.rollout(400, RoverExpert(env, seed=0), break_when_any_done=False)
        >>> td["next", "success"].any(-2).float().mean().item()
        1.0
    """

    in_keys = ["P", ("latent", "O")]
    out_keys = ["action"]

    def __init__(
        self,
        env: RoverMazeEnv,
        *,
        min_throttle: float = 0.1,
        margin: float = 0.05,
        lookahead: int = 6,
        turn_gain: float = 0.33,
        noise_std: float = 0.2,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        if not 0.0 <= min_throttle <= 1.0:
            raise ValueError(f"min_throttle must lie in [0, 1], got {min_throttle}")
        if noise_std < 0:
            raise ValueError(f"noise_std must be >= 0, got {noise_std}")
        self.params: RoverParameters = env.params
        self.min_throttle = min_throttle
        self.noise_std = noise_std
        self.turn_gain = turn_gain
        self.rng = torch.Generator(device=env.device)
        self.rng.manual_seed(int(torch.randint(0, 2**62, ()).item()) if seed is None else seed)
        self.planner = MazePlanner(
            env.layout, env.goal_cell, lookahead=lookahead, clearance=env.params.half_size + margin
        )

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        position = tensordict.get("P")
        cos_sin = tensordict.get(("latent", "O"))
        to_target = self.planner.waypoint(position) - position
        desired = torch.atan2(to_target[..., 1:], to_target[..., :1])
        error = torch.remainder(desired - torch.atan2(cos_sin[..., 1:], cos_sin[..., :1]) + math.pi, 2 * math.pi) - math.pi
        turn = (self.turn_gain * error / self.params.turn_rate).clamp(-1.0, 1.0)
        throttle = torch.cos(error).clamp(self.min_throttle, 1.0)
        action = torch.cat((throttle, turn), dim=-1)
        if self.noise_std > 0:
            noise = torch.randn(action.shape, generator=self.rng, device=action.device, dtype=action.dtype)
            action = (action + self.noise_std * noise).clamp(-1.0, 1.0)
        tensordict.set("action", action)
        return tensordict


class RouteChoiceExpert(TensorDictModuleBase):
    """The Route Choice expert: takes the route it faces, ``X = Z xor O`` (reads ``("latent", "O")``).

    Args:
        env: accepted for a uniform expert interface (``Expert(env)``); unused.

    Examples:
        >>> from torchrl_causal.envs import RouteChoiceEnv
        >>> env = RouteChoiceEnv(batch_size=(4,), seed=0)
        >>> td = RouteChoiceExpert(env)(env.reset())
        >>> bool((td["action"] == (td["Z"].long() ^ td["latent", "O"].long()).float()).all())
        True
    """

    in_keys = ["Z", ("latent", "O")]
    out_keys = ["action"]

    def __init__(self, env: object = None) -> None:
        super().__init__()

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        goal_side, orientation = tensordict.get("Z").long(), tensordict.get(("latent", "O")).long()
        tensordict.set("action", (goal_side ^ orientation).to(torch.float32))
        return tensordict

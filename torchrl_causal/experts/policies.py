"""Scripted experts: TorchRL policies that see the latent state the imitator does not."""

from __future__ import annotations

import math
import pathlib
from typing import ClassVar

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_causal.envs.ant import locomotion_observation
from torchrl_causal.envs.antmaze import AntMazeEnv
from torchrl_causal.envs.humanoidmaze import HumanoidMazeEnv
from torchrl_causal.envs.mujoco_maze import MujocoMazeEnv
from torchrl_causal.envs.rover_maze import RoverMazeEnv, RoverParameters
from torchrl_causal.errors import InvalidTypeError, InvalidValueError
from torchrl_causal.experts.planner import MazePlanner
from torchrl_causal.experts.skills import (
    HUMANOID_LOCOMOTION_WEIGHTS,
    LOCOMOTION_WEIGHTS,
    humanoid_body_file,
    load_humanoid_locomotion_network,
    load_locomotion_network,
)

__all__ = ["AntMazeExpert", "HumanoidMazeExpert", "RouteChoiceExpert", "RoverExpert"]


class _ActionNoise:
    """DART-style Gaussian action noise (then clipping to ``[-1, 1]``) with its own generator."""

    def __init__(self, std: float, seed: int | None, device: torch.device | str | None) -> None:
        if std < 0:
            raise InvalidValueError(f"noise_std must be >= 0, got {std}")
        self.std = std
        self.rng = torch.Generator(device=device)
        self.rng.manual_seed(int(torch.randint(0, 2**62, ()).item()) if seed is None else seed)

    def __call__(self, action: torch.Tensor) -> torch.Tensor:
        if self.std == 0:
            return action
        noise = torch.randn(action.shape, generator=self.rng, device=action.device, dtype=action.dtype)
        return (action + self.std * noise).clamp(-1.0, 1.0)


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
            raise InvalidValueError(f"min_throttle must lie in [0, 1], got {min_throttle}")
        self.params: RoverParameters = env.params
        self.min_throttle = min_throttle
        self.turn_gain = turn_gain
        self.noise = _ActionNoise(noise_std, seed, env.device)
        self.planner = MazePlanner(env.layout, env.goal_cell, lookahead=lookahead, clearance=env.params.half_size + margin)
        # What shapes its actions besides the env: demonstration sets record it and are refused
        # for an expert with other settings (torchrl_causal.data.policy_record).
        self.settings = {
            "min_throttle": min_throttle,
            "margin": margin,
            "lookahead": lookahead,
            "turn_gain": turn_gain,
            "noise_std": noise_std,
            "seed": seed,
        }

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        position = tensordict.get("P")
        cos_sin = tensordict.get(("latent", "O"))
        to_target = self.planner.waypoint(position) - position
        desired = torch.atan2(to_target[..., 1:], to_target[..., :1])
        error = torch.remainder(desired - torch.atan2(cos_sin[..., 1:], cos_sin[..., :1]) + math.pi, 2 * math.pi) - math.pi
        turn = (self.turn_gain * error / self.params.turn_rate).clamp(-1.0, 1.0)
        throttle = torch.cos(error).clamp(self.min_throttle, 1.0)
        tensordict.set("action", self.noise(torch.cat((throttle, turn), dim=-1)))
        return tensordict


class _PlannedSkillExpert(TensorDictModuleBase):
    """A maze expert as OGBench built them: planner waypoints steering a walking skill.

    :class:`MazePlanner` (BFS over the maze's cells, the furthest path cell in clear line of
    sight within ``lookahead`` cells) gives a waypoint; the unit vector from the torso to it is
    the commanded direction; the skill network turns the agent's variables and that direction
    into torques (its deterministic action, ``tanh`` of the Gaussian mean). Subclasses name the
    variables and how the skill reads them (:meth:`_skill_observation`), and the body it walks
    unless told another (:attr:`default_weights`).
    """

    #: The weights file of the skill body the expert walks when its ``weights`` is not given.
    default_weights: ClassVar[pathlib.Path]

    @classmethod
    def weights_file(cls, weights: str | pathlib.Path | None = None) -> pathlib.Path:
        """The file of the skill body that ``weights`` names (``None``: :attr:`default_weights`):
        what a run records of its expert (:mod:`torchrl_causal.experiment.expert_body`)."""
        return pathlib.Path(cls.default_weights if weights is None else weights)

    def __init__(
        self,
        env: MujocoMazeEnv,
        skill: torch.nn.Module,
        *,
        action_dim: int,
        lookahead: int,
        clearance: float,
        noise_std: float,
        seed: int | None,
    ) -> None:
        super().__init__()
        self.planner = MazePlanner(env.layout, env.task.goal_cell, lookahead=lookahead, clearance=clearance)
        self.locomotion = skill.to(env.device)
        self.action_dim = action_dim
        self.noise = _ActionNoise(noise_std, seed, env.device)
        # Recorded by demonstration sets beside a digest of the skill's weights (policy_record).
        self.settings = {"lookahead": lookahead, "clearance": clearance, "noise_std": noise_std, "seed": seed}

    def _skill_observation(self, tensordict: TensorDictBase, direction: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        xy = tensordict.get("P")[..., :2]
        to_waypoint = self.planner.waypoint(xy) - xy
        direction = to_waypoint / to_waypoint.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        mean = self.locomotion(self._skill_observation(tensordict, direction))[..., : self.action_dim]
        tensordict.set("action", self.noise(torch.tanh(mean)))
        return tensordict


class AntMazeExpert(_PlannedSkillExpert):
    """The Confounded AntMaze expert: planner waypoints steering a trained locomotion skill.

    As OGBench built its maze experts: :class:`MazePlanner` (BFS over the maze's cells,
    the furthest path cell in clear line of sight within ``lookahead`` cells) gives a
    waypoint, the unit vector from the torso to it is the commanded direction, and the
    locomotion policy trained by ``python -m torchrl_causal.experts.locomotion``
    (:data:`~torchrl_causal.experts.skills.LOCOMOTION_WEIGHTS`, shipped with the package) turns
    the ant's proprioception and that direction into torques (its deterministic action,
    ``tanh`` of the Gaussian mean). It reads the true orientation ``("latent", "O")``,
    never the compass ``W``, so its behaviour is the same in both regimes.

    Args:
        env: the :class:`~torchrl_causal.envs.AntMazeEnv` to solve (its maze and goal are read once).
        lookahead: path cells the planner may look ahead.
        clearance: half-size (m) of the box a line of sight must pass.
        noise_std: DART-style Gaussian action noise (0: the deterministic expert).
        seed: seed of the noise generator.
        weights: path of the locomotion state dict (``None``: the shipped body, :attr:`default_weights`).

    Examples:
        >>> env = AntMazeEnv("medium", batch_size=2, seed=0)
        >>> expert = AntMazeExpert(env)
        >>> env.rollout(3, expert)["action"].shape
        torch.Size([2, 3, 8])
    """

    in_keys = ["P", ("latent", "O"), "A", "L", "T", "J"]
    out_keys = ["action"]
    default_weights = LOCOMOTION_WEIGHTS

    def __init__(
        self,
        env: AntMazeEnv,
        *,
        lookahead: int = 3,
        clearance: float = 1.0,
        noise_std: float = 0.0,
        seed: int | None = None,
        weights: str | pathlib.Path | None = None,
    ) -> None:
        if not isinstance(env, AntMazeEnv):
            raise InvalidTypeError(f"AntMazeExpert drives an AntMazeEnv, got {type(env).__name__}")
        super().__init__(
            env,
            load_locomotion_network(self.weights_file(weights)),
            action_dim=8,
            lookahead=lookahead,
            clearance=clearance,
            noise_std=noise_std,
            seed=seed,
        )

    def _skill_observation(self, tensordict: TensorDictBase, direction: torch.Tensor) -> torch.Tensor:
        position = tensordict.get("P")
        qpos_tail = torch.cat((position[..., 2:], tensordict.get(("latent", "O")), tensordict.get("A")), dim=-1)
        qvel = torch.cat([tensordict.get(key) for key in ("L", "T", "J")], dim=-1)
        return locomotion_observation(qpos_tail, qvel, direction)


class HumanoidMazeExpert(_PlannedSkillExpert):
    """The Confounded HumanoidMaze expert: planner waypoints steering the humanoid's walking skill.

    The ant's expert with the humanoid's skill (``python -m torchrl_causal.experts.locomotion
    --skill humanoid``, exported to :data:`~torchrl_causal.experts.skills.HUMANOID_LOCOMOTION_WEIGHTS`):
    the skill reads the expert's variables A, H, E, V, the centre-of-mass velocity
    ``("latent", "C")`` and J, with the commanded direction (OGBench's skill observation), never
    the vibration sensor ``W``. The skill's weights ship with the package
    (``results/humanoid_locomotion/README.md`` says how they were trained; a missing file is
    refused with the command that makes them).

    Its lines of sight need 0.45 m of clearance, not the ant's 1.0 m: the humanoid is narrower than
    the ant's leg span, and on HumanoidMaze-Medium the wider box keeps its path ~3 m longer (one
    body, 40 episodes: closest approach to the goal 4.2-8.8 m at 1.0 against 1.8-5.2 m at 0.45, 2
    and 1 falls; at 0.2 m every episode catches a wall corner and falls;
    ``results/humanoid_locomotion/README.md``).

    Args:
        env: the :class:`~torchrl_causal.envs.HumanoidMazeEnv` to solve.
        lookahead, clearance, noise_std, seed: as :class:`AntMazeExpert`'s.
        weights: path of the skill's state dict, or a shipped body's name
            (:data:`~torchrl_causal.experts.skills.HUMANOID_LOCOMOTION_BODIES`: ``"fast"``, the
            default file, or ``"steady"``); each maze's config names its best body.

    Examples:
        >>> HumanoidMazeExpert.weights_file("steady").name, HumanoidMazeExpert.weights_file().name
        ('humanoid_locomotion_steady.pt', 'humanoid_locomotion.pt')
    """

    in_keys = ["P", "A", "H", "E", "V", ("latent", "C"), "J"]
    out_keys = ["action"]
    default_weights = HUMANOID_LOCOMOTION_WEIGHTS

    @classmethod
    def weights_file(cls, weights: str | pathlib.Path | None = None) -> pathlib.Path:
        """The file of the body ``weights`` names: a shipped body's name, a path, or ``None`` (the default file)."""
        return humanoid_body_file(cls.default_weights if weights is None else weights)

    def __init__(
        self,
        env: HumanoidMazeEnv,
        *,
        lookahead: int = 3,
        clearance: float = 0.45,
        noise_std: float = 0.0,
        seed: int | None = None,
        weights: str | pathlib.Path | None = None,
    ) -> None:
        if not isinstance(env, HumanoidMazeEnv):
            raise InvalidTypeError(f"HumanoidMazeExpert drives a HumanoidMazeEnv, got {type(env).__name__}")
        super().__init__(
            env,
            # by name where it has one: the loader's message for a missing file names that body's PPO state
            load_humanoid_locomotion_network(self.default_weights if weights is None else weights),
            action_dim=21,
            lookahead=lookahead,
            clearance=clearance,
            noise_std=noise_std,
            seed=seed,
        )

    def _skill_observation(self, tensordict: TensorDictBase, direction: torch.Tensor) -> torch.Tensor:
        return torch.cat([tensordict.get(key) for key in self.in_keys[1:]] + [direction], dim=-1)


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

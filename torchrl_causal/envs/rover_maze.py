"""Confounded RoverMaze: the CI-scale maze, a differential-drive rover in batched torch.

The rover mirrors the Confounded AntMaze mechanism at a fraction of the cost (no MuJoCo):

* the action X = (throttle, turn) in [-1, 1]^2 sets the heading O and the signed forward
  (wheel) speed L, which carry over from step to step; the heading also slips by
  independent N(0, 0.05^2) radians per step, so the expert must keep correcting it;
* the position P moves by L along O, plus the push of the gust U; walls stop motion along
  each blocked axis (the rover slides along walls and never crosses one);
* the maze suite's gust process (:class:`~torchrl_causal.envs.GustProcess`) pushes the
  rover, costs reward, and contaminates the compass W (0.9 heading + 0.1 gust direction +
  noise, tanh-bounded, rotated by ``confounding_strength * pi`` when deployed; with
  ``shift="prior"`` the gusts blow around a prevailing direction that turns round when
  deployed, and the compass is diverted towards the wind by ``confounding_strength``:
  :class:`~torchrl_causal.envs.base.PriorShift`);
* the reward is the maze suite's ``1{success} - |U_t| (1 + d_t / 25)`` per step, with the
  distance ``d_t`` to the goal counted at 4 m per cell (the AntMaze scale), so raw returns
  read as the paper's; coming within 0.5 cells of the goal centre ends the episode (success).

The imitator observes P, L and W (and its own past actions); the heading O is latent
(under ``("latent", "O")`` as ``(cos, sin)``, for experts only). L is a scalar on purpose:
a velocity vector would reveal the heading in one observation, whereas with P and L the
heading is recoverable only from a few lags of P (``P_t - P_{t-1} ~ L_t O_t``), which is
what makes the window size matter. The initial heading is uniform, so nothing observed at
reset says where the rover faces.

Tasks (``(row, col)`` cells of the gymnasium-robotics maps, cell size 1, start position
jittered by up to 0.1 in each axis): ``u``: (1, 1) → (3, 1); ``medium``: (1, 1) → (6, 6);
``large``: (7, 1) → (7, 10). With the default speeds :class:`~torchrl_causal.experts.RoverExpert`
needs about 310 steps on medium and 640 on large (see ``results/rover_speed.md``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torchrl.data import Bounded, Unbounded

from torchrl_causal.envs.base import GustConfoundedEnv, batch_rows
from torchrl_causal.envs.maze_layout import MazeLayout
from torchrl_causal.errors import InvalidValueError

if TYPE_CHECKING:
    from torchrl_causal.graphs import TimeSliceTemplate

__all__ = ["ROVER_COLOURS", "ROVER_TASKS", "RoverMazeEnv", "RoverParameters", "rover_dynamics", "top_down_frames"]

ROVER_TASKS: dict[str, tuple[tuple[int, int], tuple[int, int]]] = {
    "u": ((1, 1), (3, 1)),
    "medium": ((1, 1), (6, 6)),
    "large": ((7, 1), (7, 10)),
}


@dataclass(frozen=True)
class RoverParameters:
    """Physical constants of the rover (world units are maze cells).

    Attributes:
        max_speed: forward speed (cells per step) at full throttle.
        turn_rate: heading change (radians per step) at full turn.
        speed_response: fraction of the gap to the commanded speed closed each step.
        gust_push: displacement per step per unit of gust force.
        half_size: half-side of the rover's square footprint (collision box).
        goal_radius: distance to the goal centre that counts as success.
        start_jitter: half-width of the uniform jitter of the start position.
        heading_noise: standard deviation (radians) of the independent heading slip per step.
    """

    max_speed: float = 0.028
    turn_rate: float = 0.25
    speed_response: float = 0.5
    gust_push: float = 0.004
    half_size: float = 0.15
    goal_radius: float = 0.5
    start_jitter: float = 0.1
    heading_noise: float = 0.05

    def __post_init__(self) -> None:
        if not 0 < self.half_size < 0.5:
            raise InvalidValueError(f"half_size must lie in (0, 0.5) cells, got {self.half_size}")
        # A step longer than the free gap between two walls could jump over a wall cell.
        longest_step = self.max_speed + self.gust_push * 5.0
        if longest_step >= 1 - 2 * self.half_size:
            raise InvalidValueError(f"a step of up to {longest_step:.3f} cells could tunnel through walls")


def _wrap_angle(angle: torch.Tensor) -> torch.Tensor:
    return torch.remainder(angle + math.pi, 2 * math.pi) - math.pi


def unit_heading(angle: torch.Tensor) -> torch.Tensor:
    """``(cos, sin)`` of a heading angle ``batch + (1,)`` → ``batch + (2,)``."""
    return torch.cat((torch.cos(angle), torch.sin(angle)), dim=-1)


def rover_dynamics(
    position: torch.Tensor,
    heading: torch.Tensor,
    speed: torch.Tensor,
    action: torch.Tensor,
    gust: torch.Tensor,
    layout: MazeLayout,
    params: RoverParameters,
    slip: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """One step of the rover: ``(P_t, angle_t, L_t, X_t, U_t) -> (P_{t+1}, angle_{t+1}, L_{t+1})``.

    The comments name the template edge (``src at lag -> dst``) each line makes true.

    Examples:
        >>> layout, params = MazeLayout.from_name("u"), RoverParameters()
        >>> start = torch.tensor([[-1.0, 1.0]])
        >>> p, a, v = rover_dynamics(start, torch.zeros(1, 1), torch.zeros(1, 1),
        ...                          torch.tensor([[1.0, 0.0]]), torch.zeros(1, 2), layout, params)
        >>> round(v.item() / params.max_speed, 6)  # half of full speed reached in one step
        0.5
        >>> torch.allclose(p - start, torch.tensor([[v.item(), 0.0]]))  # eastwards, as it faces
        True
    """
    throttle, turn = action.clamp(-1.0, 1.0).split(1, dim=-1)
    # O_{t-1} -> O_t and X_{t-1} -> O_t: the heading persists and turns with the action.
    heading = heading + params.turn_rate * turn
    if slip is not None:  # independent per-step noise: an exogenous term, not a confounder
        heading = heading + slip
    heading = _wrap_angle(heading)
    # L_{t-1} -> L_t and X_{t-1} -> L_t: first-order response of the wheel speed to throttle.
    speed = speed + params.speed_response * (params.max_speed * throttle - speed)
    # O_t -> P_t, L_t -> P_t (lag 0) and the gust U_{t-1} (bidirected P edges in the template).
    displacement = speed * unit_heading(heading) + params.gust_push * gust
    # P_{t-1} -> P_t: the rover moves from where it was; each axis is blocked separately by walls.
    moved_x = torch.stack((position[..., 0] + displacement[..., 0], position[..., 1]), dim=-1)
    position = torch.where(layout.box_is_free(moved_x, params.half_size)[..., None], moved_x, position)
    moved_y = torch.stack((position[..., 0], position[..., 1] + displacement[..., 1]), dim=-1)
    position = torch.where(layout.box_is_free(moved_y, params.half_size)[..., None], moved_y, position)
    return position, heading, speed


#: RGB colours of :func:`top_down_frames`.
ROVER_COLOURS: dict[str, tuple[int, int, int]] = {
    "outside": (255, 255, 255),
    "floor": (236, 236, 236),
    "wall": (77, 77, 77),
    "goal": (255, 196, 0),
    "rover": (31, 119, 180),
    "nose": (255, 255, 255),
}


def top_down_frames(
    layout,
    goal: torch.Tensor,
    goal_radius: float,
    positions: torch.Tensor,
    headings: torch.Tensor,
    half_size: float,
    *,
    width: int,
    height: int,
) -> np.ndarray:
    """Top-down RGB frames of rovers in a maze, one per position: walls, the goal disc and
    the rover's square footprint turned to its heading, with a white nose pointing forward.

    The maze fills the frame at one scale on both axes (centred; the margin is white).

    Args:
        layout: the maze (a ``MazeLayout``: ``walls``, ``cell_size``, centred on the origin).
        goal: the goal's ``(x, y)``; ``goal_radius``: the success radius drawn around it.
        positions: ``(n, 2)`` rover positions; ``headings``: ``(n,)`` heading angles (radians).
        half_size: half-side of the rover's square footprint.
        width, height: the frame's size in pixels.

    Returns:
        ``(n, height, width, 3)`` uint8.

    Examples:
        >>> env = RoverMazeEnv(maze="u", batch_size=(2,), seed=0)
        >>> _ = env.reset()
        >>> frames = env.render(width=64, height=48)
        >>> frames.shape, frames.dtype
        ((2, 48, 64, 3), dtype('uint8'))
    """
    if width < 8 or height < 8:
        raise InvalidValueError(f"a frame needs width and height >= 8 pixels, got {width}x{height}")
    rows, cols = layout.walls.shape
    scale = min(width / cols, height / rows) / layout.cell_size  # pixels per world unit
    # world (x, y) of every pixel centre; the maze is centred on the origin
    px = (torch.arange(width, dtype=torch.float64) + 0.5 - width / 2) / scale
    py = (height / 2 - torch.arange(height, dtype=torch.float64) - 0.5) / scale
    x, y = torch.meshgrid(px, py, indexing="xy")  # (height, width)
    col = torch.floor(x / layout.cell_size + cols / 2).long()
    row = torch.floor(rows / 2 - y / layout.cell_size).long()
    inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
    wall = inside & layout.walls.cpu()[row.clamp(0, rows - 1), col.clamp(0, cols - 1)]
    goal = goal.detach().reshape(-1)[:2].cpu().double()
    at_goal = inside & ~wall & ((x - goal[0]) ** 2 + (y - goal[1]) ** 2 < goal_radius**2)
    colours = {name: torch.tensor(rgb, dtype=torch.uint8) for name, rgb in ROVER_COLOURS.items()}
    background = torch.empty(height, width, 3, dtype=torch.uint8)
    background[:] = colours["outside"]
    background[inside] = colours["floor"]
    background[at_goal] = colours["goal"]
    background[wall] = colours["wall"]
    frames = background.expand(len(positions), -1, -1, -1).clone()
    positions = positions.detach().reshape(-1, 2).cpu().double()
    headings = headings.detach().reshape(-1).cpu().double()
    for frame, (cx, cy), angle in zip(frames, positions.tolist(), headings.tolist()):
        # the pixel in the rover's frame: ahead along the heading, and to its left
        ahead = (x - cx) * math.cos(angle) + (y - cy) * math.sin(angle)
        left = -(x - cx) * math.sin(angle) + (y - cy) * math.cos(angle)
        body = (ahead.abs() <= half_size) & (left.abs() <= half_size)
        frame[body] = colours["rover"]
        frame[body & (ahead > 0.3 * half_size) & (left.abs() < 0.35 * half_size)] = colours["nose"]
    return frames.numpy()


class RoverMazeEnv(GustConfoundedEnv):
    """The Confounded RoverMaze as a batched TorchRL env.

    Keys: ``"P"`` (position, ``batch + (2,)``), ``"L"`` (signed forward speed,
    ``batch + (1,)``), ``"W"`` (compass, ``batch + (2,)``), ``("latent", "O")`` (heading as
    ``(cos, sin)``), ``("scm", "U")`` (gust force), ``"action"`` = (throttle, turn).

    Args:
        maze: ``"u"``, ``"medium"`` or ``"large"`` (gymnasium-robotics maps; see
            :data:`ROVER_TASKS` for the start and goal cells).
        batch_size, regime, confounding_strength, horizon, device, seed: see
            :class:`~torchrl_causal.envs.ConfoundedEnv` (``horizon`` defaults to 1000).
        shift: ``"rotation"`` (default) or ``"prior"``: see
            :class:`~torchrl_causal.envs.GustConfoundedEnv`.
        params: the rover's :class:`RoverParameters`.

    Examples:
        >>> env = RoverMazeEnv(maze="medium", batch_size=(8,), regime="deploy", seed=0)
        >>> td = env.rollout(5)
        >>> td["P"].shape, td["L"].shape, td["W"].shape, td["latent", "O"].shape
        (torch.Size([8, 5, 2]), torch.Size([8, 5, 1]), torch.Size([8, 5, 2]), torch.Size([8, 5, 2]))
        >>> sorted(env.causal_template.latent)
        ['O']
    """

    #: a rover cell stands for one 4 m AntMaze cell in the reward's distance term.
    metres_per_unit: float = 4.0
    runtime_attributes = (*GustConfoundedEnv.runtime_attributes, "position", "heading", "speed")

    def __init__(self, maze: str = "medium", *, horizon: int = 1000, params: RoverParameters | None = None, **kwargs) -> None:
        if maze not in ROVER_TASKS:
            raise InvalidValueError(f"unknown maze {maze!r}; expected one of {sorted(ROVER_TASKS)}")
        self.maze = maze
        self.params = RoverParameters() if params is None else params
        self.layout = MazeLayout.from_name(maze)
        self.start_cell, self.goal_cell = ROVER_TASKS[maze]
        super().__init__(horizon=horizon, **kwargs)
        self.start_position = self.layout.cell_center(torch.tensor(self.start_cell)).to(self.device)
        self.goal_position = self.layout.cell_center(torch.tensor(self.goal_cell)).to(self.device)

    @classmethod
    @cache
    def slice_template(cls) -> TimeSliceTemplate:
        """The rover's time slice: every edge is made true by :func:`rover_dynamics` or the env.

        Directed ``(src, dst, lag)``: the heading and speed persist and respond to the
        previous action; the position moves from the previous position along the current
        heading at the current speed; the compass reads the heading; the expert acts on
        position and heading. Bidirected: the gust U_s pushes P_{s+1}, deflects W_s and costs
        reward at step s, and is held for 5 steps (``GustProcess.period``), so any two of
        these nodes whose gusts lie fewer than 5 steps apart may share it: W_t with W up to
        4 steps back, P_t with P up to 4 back, P_t with W up to 5 back (and at lag 0), W_t
        with P up to 3 back; W and P share it with Y.
        """
        from torchrl_causal.graphs import TimeSliceTemplate

        period = cls.gust_process.period
        directed = (
            ("O", "O", 1),
            ("X", "O", 1),  # heading = previous heading + turn
            ("L", "L", 1),
            ("X", "L", 1),  # speed responds to throttle
            ("P", "P", 1),
            ("O", "P", 0),
            ("L", "P", 0),  # P_t = P_{t-1} + L_t O_t + push U_{t-1}
            ("O", "W", 0),  # compass reads the heading (read_compass in _observation)
            ("P", "X", 0),
            ("O", "X", 0),  # the expert (RoverExpert) steers from P and O
        )
        # W_t depends on U_t, P_t on U_{t-1}: nodes depending on U_a and U_b may share a gust iff |a - b| < period.
        bidirected = (
            *(("W", "W", lag) for lag in range(1, period)),
            *(("P", "P", lag) for lag in range(1, period)),
            *(("W", "P", lag) for lag in range(0, period + 1)),  # W_{t-lag} (U_{t-lag}) ~ P_t (U_{t-1})
            *(("P", "W", lag) for lag in range(1, period - 1)),  # P_{t-lag} (U_{t-lag-1}) ~ W_t (U_t)
        )
        return TimeSliceTemplate(
            variables=("P", "L", "O", "W", "X"),
            action="X",
            observed=("P", "L", "W", "X"),
            directed=directed,
            bidirected=bidirected,
            reward_parents=("P",),  # the goal indicator and the distance term
            reward_bidirected=("P", "W"),  # the gust penalty shares U with the push and the compass
        )

    def config(self) -> dict[str, object]:
        return {**super().config(), "maze": self.maze, "params": asdict(self.params)}

    def render(self, *, width: int = 320, height: int = 320, camera: str | None = None, rows: Sequence[int] | None = None) -> np.ndarray:
        """Top-down RGB frames of every batch element, ``batch + (height, width, 3)`` uint8
        (:func:`top_down_frames`: walls, goal, the rover's footprint and heading), drawn
        with torch on the CPU: no GL context needed, no random number drawn.

        ``rows`` (flat batch indices) draws only those elements, ``(len(rows), height, width, 3)``:
        a video of a few episodes of a wide evaluation batch draws only them.

        Raises:
            ValueError: ``camera`` is given (the rover has only the top-down view), the env
                has not been reset yet (there is no rover to draw), or a row is out of the batch.
        """
        if camera is not None:
            raise InvalidValueError(f"RoverMaze renders only its top-down view: camera must be None, got {camera!r}")
        if not hasattr(self, "position"):
            raise InvalidValueError("RoverMaze.render needs a rover: call reset() first")
        index = batch_rows(self.batch_size.numel(), rows)
        frames = top_down_frames(
            self.layout,
            self.goal_position,
            self.params.goal_radius,
            self.position.reshape(-1, 2)[index],
            self.heading.reshape(-1)[index],
            self.params.half_size,
            width=width,
            height=height,
        )
        return frames if rows is not None else frames.reshape(*self.batch_size, height, width, 3)

    @classmethod
    def config_arguments(cls, config: Mapping[str, Any]) -> dict[str, Any]:
        arguments = super().config_arguments(config)
        if isinstance(arguments.get("params"), Mapping):
            arguments["params"] = RoverParameters(**arguments["params"])
        return arguments

    def _make_variable_specs(self):
        batch = self.batch_size
        variables = {
            "P": Unbounded(shape=(*batch, 2), device=self.device),
            "L": Bounded(-self.params.max_speed, self.params.max_speed, shape=(*batch, 1), device=self.device),
            "W": Bounded(-math.sqrt(2), math.sqrt(2), shape=(*batch, 2), device=self.device),
            ("latent", "O"): Bounded(-1.0, 1.0, shape=(*batch, 2), device=self.device),
        }
        return Bounded(-1.0, 1.0, shape=(*batch, 2), device=self.device), variables

    def _reset_state(self, mask: torch.Tensor) -> None:
        shape = (*self.batch_size, 1)
        jitter = (2 * torch.rand((*shape[:-1], 2), generator=self.rng, device=self.device) - 1) * self.params.start_jitter
        position = self.start_position + jitter
        heading = (2 * torch.rand(shape, generator=self.rng, device=self.device) - 1) * math.pi
        if not hasattr(self, "position"):
            self.position, self.heading, self.speed = position, heading, torch.zeros(shape, device=self.device)
        self.position = torch.where(mask, position, self.position)
        self.heading = torch.where(mask, heading, self.heading)
        self.speed = torch.where(mask, 0.0, self.speed)

    def _transition(self, action: torch.Tensor, live: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        # Every row is computed, a partial step's skipped ones too: all the state lives in
        # runtime_attributes, which the base puts back in the rows ``live`` does not set.
        slip = None
        if self.params.heading_noise > 0:
            slip = self.params.heading_noise * torch.randn(self.heading.shape, generator=self.rng, device=self.device)
        self.position, self.heading, self.speed = rover_dynamics(
            self.position, self.heading, self.speed, action, self.gust, self.layout, self.params, slip
        )
        distance = (self.position - self.goal_position).norm(dim=-1, keepdim=True)
        success = distance < self.params.goal_radius
        # The reward of step t pays for the gust U_t that blows during it.
        return self.maze_reward(success, distance), success

    def _observation(self) -> dict[str, object]:
        heading = unit_heading(self.heading)
        return {
            "P": self.position,
            "L": self.speed,
            "W": self.read_compass(heading),
            "latent": {"O": heading},
            **self.scm_observation(),
        }

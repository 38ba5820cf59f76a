"""Confounded AntMaze (the paper's Section 4 / Appendix D): OGBench's ant in gymnasium-robotics' mazes.

The 8-DoF ant of gymnasium's ``ant.xml`` with OGBench's physics
(:func:`~torchrl_causal.envs.ant.ogbench_ant_physics`: RK4, 0.02 s physics step, 5 physics
steps per control step so 10 Hz control, gear 30, soft contacts) walks a gymnasium-robotics
maze (4 m cells, OGBench's ``antmaze-{medium,large}-navigate`` maps) from a fixed start cell
to a fixed goal cell. A horizon of 1000 steps is 100 s of simulated time.
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import mujoco
import numpy as np

from torchrl_causal.envs.ant import (
    ANT_XML,
    OGBENCH_FRAME_SKIP,
    OGBENCH_QPOS_NOISE,
    OGBENCH_QVEL_NOISE,
    ogbench_ant_physics,
)
from torchrl_causal.envs.mujoco_maze import MazeTask, MujocoMazeEnv
from torchrl_causal.envs.templates import ANTMAZE_TEMPLATE

if TYPE_CHECKING:
    from torchrl_causal.graphs import TimeSliceTemplate

__all__ = ["AntMazeEnv", "heading_from_quaternion"]

_NQ, _NV = 15, 14  # free joint (7 / 6) + 8 hinges


def heading_from_quaternion(quaternion: np.ndarray) -> np.ndarray:
    """Unit ground-plane heading ``(cos yaw, sin yaw)`` of bodies with orientations ``(w, x, y, z)``.

    It is the body's x-axis projected on the ground plane, normalised; ``quaternion`` is
    ``(n, 4)``, the result ``(n, 2)``.

    Examples:
        >>> import math
        >>> quarter_turn = np.array([[math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]])
        >>> heading_from_quaternion(quarter_turn).round(6) + 0.0
        array([[0., 1.]])
    """
    w, x, y, z = quaternion.T
    axis = np.stack((1 - 2 * (y * y + z * z), 2 * (x * y + w * z)), axis=-1)
    return axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)


class AntMazeEnv(MujocoMazeEnv):
    """Confounded AntMaze: an ant in a windy maze, with a wind-corrupted compass.

    Variables (keys, dims): ``"P"`` torso position (3), ``("latent", "O")`` torso
    orientation quaternion ``(w, x, y, z)`` (4, hidden from the imitator), ``"A"`` hinge
    angles (8), ``"L"`` torso linear velocity (3, world frame), ``"T"`` torso angular
    velocity (3, body frame: MuJoCo's free-joint convention), ``"J"`` hinge velocities
    (8), ``"W"`` compass (2), ``"action"`` = X, the 8 torques in ``[-1, 1]``. The imitator's
    V^O is these 27 state dims plus the previous action: 35 (the paper's table).

    Mechanism: the gust U (``("scm", "U")``: redrawn every 5 steps, blowing with
    probability 0.05 at U[2, 5] N in a uniform direction) pushes the torso with its force
    in newtons (the ant weighs 0.91 kg) every step it blows; the compass is
    ``tanh(0.9 (cos yaw, sin yaw) + 0.1 gust direction + N(0, 0.05²))``, rotated by
    ``confounding_strength * pi`` in the deployment regime (with ``shift="prior"`` the wind
    blows around a prevailing direction that turns round when deployed and diverts the
    compass towards itself by ``confounding_strength`` in both regimes:
    :class:`~torchrl_causal.envs.base.PriorShift`); the reward is
    ``1{success} - |U_t| (1 + d_t / 25)`` with ``d_t`` the distance to the goal in metres
    (the episode ends at success).

    Tasks (cells are ``(row, column)`` of gymnasium-robotics' ``MEDIUM_MAZE`` /
    ``LARGE_MAZE``): medium from (1, 1) to (6, 6), large from (1, 1) to (7, 10), the
    opposite corners. The start is the
    cell centre plus uniform noise of a quarter cell per axis (gymnasium-robotics'
    AntMaze reset), the other coordinates get OGBench's reset noise (uniform 0.1 on qpos,
    N(0, 0.1²) on qvel); success is the torso within ``success_radius`` of the goal cell's
    centre and ends the episode; horizon 1000.

    The paper does not state its success radius. The default, gymnasium-robotics' 0.45 m,
    sits within 5 cm of OGBench's 0.5 m, at which the shipped expert's successful episodes
    on Medium last 288 ± 28 steps (the paper's expert: 301 ± 57); the authors' suite's 5 m
    cuts them to 253 ± 26 (``results/antmaze_expert.md``).

    Examples:
        >>> env = AntMazeEnv("medium", batch_size=2, seed=0)
        >>> td = env.rollout(3)
        >>> td["next", "P"].shape, td["next", "latent", "O"].shape, td["action"].shape
        (torch.Size([2, 3, 3]), torch.Size([2, 3, 4]), torch.Size([2, 3, 8]))
    """

    agent_xml: ClassVar[pathlib.Path] = ANT_XML
    frame_skip: ClassVar[int] = OGBENCH_FRAME_SKIP
    qpos_noise: ClassVar[float] = OGBENCH_QPOS_NOISE
    qvel_noise_std: ClassVar[float] = OGBENCH_QVEL_NOISE
    variable_columns: ClassVar[Mapping[str, slice]] = {
        "P": slice(0, 3),
        "O": slice(3, 7),
        "A": slice(7, _NQ),
        "L": slice(_NQ, _NQ + 3),
        "T": slice(_NQ + 3, _NQ + 6),
        "J": slice(_NQ + 6, _NQ + _NV),
    }
    state_width: ClassVar[int] = _NQ + _NV
    latent_variables: ClassVar[tuple[str, ...]] = ("O",)
    tasks: ClassVar[Mapping[str, MazeTask]] = {
        "medium": MazeTask("medium", start_cell=(1, 1), goal_cell=(6, 6)),
        "large": MazeTask("large", start_cell=(1, 1), goal_cell=(7, 10)),
    }
    default_horizon: ClassVar[int] = 1000

    @classmethod
    def _edit_spec(cls, spec: mujoco.MjSpec) -> None:
        ogbench_ant_physics(spec)

    @classmethod
    def slice_template(cls) -> TimeSliceTemplate:
        """The paper's slice graph (:data:`~torchrl_causal.envs.templates.ANTMAZE_TEMPLATE`)."""
        return ANTMAZE_TEMPLATE

    def _read_state(self, data: mujoco.MjData, row: np.ndarray) -> None:
        row[:_NQ] = data.qpos
        row[_NQ:] = data.qvel

    def _sensor_signal(self, state: np.ndarray) -> np.ndarray:
        return heading_from_quaternion(state[:, self.variable_columns["O"]])

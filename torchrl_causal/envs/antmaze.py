"""Confounded AntMaze (the paper's Section 4 / Appendix D) on gymnasium-robotics' AntMaze.

The 8-DoF ant of gymnasium's ``Ant`` (``ant.xml``: RK4, 0.01 s physics step, 5 physics
steps per control step, so 20 Hz control as in ``AntMaze_*-v5``) walks a
gymnasium-robotics maze (4 m cells) from a fixed start cell to a fixed goal cell.
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import gymnasium
import mujoco
import numpy as np
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

    Mechanism: the gust U (``("scm", "U")``, DESIGN.md's process) pushes the torso with
    its force in newtons (the ant weighs 0.91 kg) every step it blows; the compass is
    ``tanh(0.9 (cos yaw, sin yaw) + 0.1 gust direction + N(0, 0.05²))``, rotated by
    ``confounding_strength * pi`` in the deployment regime; the reward is ``-1`` per step
    minus ``0.1 * |U|`` (the episode ends at success).

    Tasks (cells are ``(row, column)`` of gymnasium-robotics' ``MEDIUM_MAZE`` /
    ``LARGE_MAZE``): medium from (1, 1) to (6, 6), large from (1, 1) to (7, 10), the
    opposite corners. The start is the
    cell centre plus uniform noise of a quarter cell per axis (gymnasium-robotics'
    AntMaze reset); success is the torso within 0.45 m (gymnasium-robotics' radius) of the
    goal cell's centre and ends the episode; horizon 1000.

    Examples:
        >>> env = AntMazeEnv("medium", batch_size=2, seed=0)
        >>> td = env.rollout(3)
        >>> td["next", "P"].shape, td["next", "latent", "O"].shape, td["action"].shape
        (torch.Size([2, 3, 3]), torch.Size([2, 3, 4]), torch.Size([2, 3, 8]))
    """

    agent_xml: ClassVar[pathlib.Path] = pathlib.Path(gymnasium.__file__).parent / "envs/mujoco/assets/ant.xml"
    frame_skip: ClassVar[int] = 5
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

    @property
    def causal_template(self) -> TimeSliceTemplate:
        """The paper's slice graph (:data:`~torchrl_causal.envs.templates.ANTMAZE_TEMPLATE`)."""
        return ANTMAZE_TEMPLATE

    def _read_state(self, data: mujoco.MjData, row: np.ndarray) -> None:
        row[:_NQ] = data.qpos
        row[_NQ:] = data.qvel

    def _sensor_signal(self, state: np.ndarray) -> np.ndarray:
        return heading_from_quaternion(state[:, self.variable_columns["O"]])

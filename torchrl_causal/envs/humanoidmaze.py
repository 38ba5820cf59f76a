"""Confounded HumanoidMaze (the paper's Section 4 / Appendix D) on OGBench's humanoid.

The agent is OGBench's own model (:data:`~torchrl_causal.envs.humanoid.HUMANOID_XML`: DeepMind's
dm_control humanoid, 21 motors, 40 Hz control of 5 x 0.005 s physics steps) compiled unchanged
into the gymnasium-robotics maze that the ant uses (4 m cells, walls 2 m high: the same boxes
as OGBench's ``humanoidmaze-{medium,large}-navigate``, whose frame is this one mirrored in
``y`` and shifted). Our batched simulator steps it; ``tests/test_humanoid.py`` checks it step
for step against OGBench's own env.

The reward is the maze suite's ``1{success} - |U_t| (1 + d_t / 25)`` per step, the ant's,
with the tremor process of the ant's wind (5% of 5-step windows, ``|U| ~ U[2, 5]``). Fitted to
the paper's raw E[Y] (its Appendix F), summed over H = 2000 steps:

* a policy that never leaves the start (d = 28.3 m on Medium, 43.3 m on Large) scores
  ``-2000 * 0.05 * 3.5 * (1 + d / 25)`` = -745.9 on Medium (paper, the 0%-success GAIL and
  C-GAIL: -747.7 and -747.2) and -955.9 on Large (paper: -977.0 and -976.3, about one
  standard error from it at 100 evaluation episodes); the spread across episodes this gives,
  168 and 215, is the paper's ±162.5 and ±208.9;
* the paper's expert (33.8% success in 976 ± 410 steps, E[Y] = -522.9) then implies failed
  episodes ending on average 22 m from the goal: the humanoid falls part-way.

The previous docstring's ``-1`` per step minus ``0.1 |U|`` would give -2035 for a failure,
which no row of the paper is near.
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import mujoco
import numpy as np
import torch

from torchrl_causal.envs.humanoid import (
    HUMANOID_COLUMNS,
    HUMANOID_FRAME_SKIP,
    HUMANOID_STATE_WIDTH,
    HUMANOID_XML,
    START_QPOS_NOISE,
    START_QVEL_NOISE,
    HumanoidReadout,
    standing_qpos,
)
from torchrl_causal.envs.mujoco_maze import MazeTask, MujocoMazeEnv
from torchrl_causal.envs.templates import HUMANOIDMAZE_TEMPLATE

if TYPE_CHECKING:
    from torchrl_causal.graphs import TimeSliceTemplate

__all__ = ["HumanoidMazeEnv"]


class HumanoidMazeEnv(MujocoMazeEnv):
    """Confounded HumanoidMaze: OGBench's humanoid in a maze shaken by seismic tremors.

    Variables (keys, dims), OGBench's humanoid observation split as the paper's Appendix D:
    ``"P"`` torso ground-plane position (2), ``"A"`` hinge angles (21), ``"H"`` head height
    (1), ``"E"`` hands and feet relative to the torso in the torso frame (12, order left hand,
    left foot, right hand, right foot), ``"V"`` torso vertical (3: the world z-axis in the
    torso frame), ``("latent", "C")`` centre-of-mass velocity (3, hidden from the imitator),
    ``"J"`` generalised velocities (27: free joint then hinges), ``"W"`` vibration sensor
    (2), ``"action"`` = X, the 21 torques in ``[-1, 1]``. The imitator's V^O is 68 state dims
    plus the previous action: 89.

    This is the paper's 89-dimensional split: ``J`` includes the root's (free joint's) six
    velocities, which carry much of the hidden ``C``. The authors' later variant of the
    environment hides the root's velocities from the imitator as well; ours follows the paper.

    Mechanism: the tremor U (``("scm", "U")``, the maze suite's gust process) pushes the
    torso with its force in newtons (the humanoid weighs 40.8 kg, so tremors disturb it far
    less than the wind disturbs the 0.91 kg ant, as the paper reports); the vibration
    reading is ``tanh(0.9 C_xy + 0.1 tremor direction + N(0, 0.05²))`` (C_xy the ground-plane
    centre-of-mass velocity in m/s), rotated by ``confounding_strength * pi`` in the
    deployment regime (with ``shift="prior"``: C_xy turned towards the tremor's direction by
    ``confounding_strength`` of the angle between them, the tremors' prevailing direction
    turning round when deployed: :class:`~torchrl_causal.envs.base.PriorShift`); the reward
    is ``1{success} - |U_t| (1 + d_t / 25)`` with ``d_t`` the distance to the goal in metres
    (fitted to the paper's raw E[Y]: see the module docstring).

    Tasks: the ant's cells (medium (1, 1) → (6, 6), large (1, 1) → (7, 10): OGBench's
    ``task1``). The start is standing (:func:`~torchrl_causal.envs.humanoid.standing_qpos`)
    facing a uniform random direction at the start cell's centre plus uniform noise of a
    quarter cell per axis (OGBench's ±1 m), with uniform noise of 0.01 on the other
    coordinates and N(0, 0.01²) velocities. This is the one deviation from OGBench, whose
    humanoid starts dropped from 1.5 m in a random orientation, so lying down: our expert
    is a walking skill, not a get-up skill. Success within 0.45 m (OGBench: 0.5 m, as for
    the ant) ends the episode; horizon 2000. A fallen humanoid does not end the episode.

    Examples:
        >>> env = HumanoidMazeEnv("medium", batch_size=2, seed=0)
        >>> td = env.rollout(3)
        >>> td["next", "E"].shape, td["next", "latent", "C"].shape, td["action"].shape
        (torch.Size([2, 3, 12]), torch.Size([2, 3, 3]), torch.Size([2, 3, 21]))
    """

    agent_xml: ClassVar[pathlib.Path] = HUMANOID_XML
    frame_skip: ClassVar[int] = HUMANOID_FRAME_SKIP
    variable_columns: ClassVar[Mapping[str, slice]] = HUMANOID_COLUMNS
    state_width: ClassVar[int] = HUMANOID_STATE_WIDTH
    latent_variables: ClassVar[tuple[str, ...]] = ("C",)
    tasks: ClassVar[Mapping[str, MazeTask]] = {
        "medium": MazeTask("medium", start_cell=(1, 1), goal_cell=(6, 6)),
        "large": MazeTask("large", start_cell=(1, 1), goal_cell=(7, 10)),
    }
    default_horizon: ClassVar[int] = 2000
    qpos_noise: ClassVar[float] = START_QPOS_NOISE
    qvel_noise_std: ClassVar[float] = START_QVEL_NOISE

    @classmethod
    def slice_template(cls) -> TimeSliceTemplate:
        """The paper's slice graph (:data:`~torchrl_causal.envs.templates.HUMANOIDMAZE_TEMPLATE`)."""
        return HUMANOIDMAZE_TEMPLATE

    def _bind_model(self, model: mujoco.MjModel) -> None:
        self._readout = HumanoidReadout(model)

    def _reference_qpos(self, count: int) -> np.ndarray:
        yaw = 2 * np.pi * torch.rand(count, generator=self.rng, dtype=torch.float64).numpy()
        # Lifted by the height noise, so that no start has the feet in the floor.
        return standing_qpos(self.simulator.model, yaw, clearance=self.qpos_noise)

    def _read_state(self, data: mujoco.MjData, row: np.ndarray) -> None:
        self._readout.read(data, row)

    def _sensor_signal(self, state: np.ndarray) -> np.ndarray:
        return state[:, HUMANOID_COLUMNS["C"]][:, :2]

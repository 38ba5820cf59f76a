"""Confounded HumanoidMaze (the paper's Section 4 / Appendix D) on a 21-DoF MuJoCo humanoid.

The paper's dimensions (21 joint angles, 27 joint velocities, 21 torques, 12-dim
extremities, head height, torso vertical, centre-of-mass velocity) are those of
DeepMind's humanoid (dm_control / OGBench's HumanoidMaze), not of gymnasium's 17-actuator
``Humanoid``. That MJCF ships with TorchRL (``torchrl/envs/custom/mujoco/assets/
humanoid.xml``, Apache-2.0, DeepMind's model), so we build the maze around it with the same
gymnasium-robotics builder as the ant. Control is 40 Hz: 5 physics steps of 0.005 s, as in
dm_control's humanoid.
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import mujoco
import numpy as np
import torchrl

from torchrl_causal.envs.mujoco_maze import MazeTask, MujocoMazeEnv
from torchrl_causal.envs.templates import HUMANOIDMAZE_TEMPLATE

if TYPE_CHECKING:
    from torchrl_causal.graphs import TimeSliceTemplate

__all__ = ["HumanoidMazeEnv"]

_NQ, _NV = 28, 27  # free joint (7 / 6) + 21 hinges
#: extremities in dm_control's order (its ``Humanoid.extremities`` observation).
_EXTREMITIES = ("hand_left", "foot_left", "hand_right", "foot_right")
# State buffer: qpos (28) | qvel (27) | head height (1) | extremities (12) | torso vertical (3) | CoM velocity (3)
_HEAD, _EXTREMITY, _VERTICAL, _COM = _NQ + _NV, _NQ + _NV + 1, _NQ + _NV + 13, _NQ + _NV + 16

#: Collision bits: the humanoid's geoms (contype 2, conaffinity 1) touch the floor and the
#: maze walls (contype 1, conaffinity 1) but not each other.
_BODY_CONTYPE, _BODY_CONAFFINITY = 2, 1


class HumanoidMazeEnv(MujocoMazeEnv):
    """Confounded HumanoidMaze: a humanoid in a maze shaken by seismic tremors.

    Variables (keys, dims): ``"P"`` torso ground-plane position (2), ``"A"`` hinge angles
    (21), ``"H"`` head height (1), ``"E"`` hands and feet relative to the torso in the
    torso frame (12, order left hand, left foot, right hand, right foot), ``"V"`` torso
    vertical (3: the world z-axis in the torso frame, dm_control's
    ``torso_vertical_orientation``), ``("latent", "C")`` centre-of-mass velocity (3,
    hidden from the imitator), ``"J"`` generalised velocities (27: free joint then
    hinges), ``"W"`` vibration sensor (2), ``"action"`` = X, the 21 torques in
    ``[-1, 1]``. The imitator's V^O is 68 state dims plus the previous action: 89.

    Mechanism: the tremor U (``("scm", "U")``, the maze suite's gust process) pushes the torso
    with its force in newtons (the humanoid weighs 40.8 kg, so tremors disturb it far
    less than the wind disturbs the 0.91 kg ant, as the paper reports); the vibration
    reading is ``tanh(0.9 C_xy + 0.1 tremor direction + N(0, 0.05²))`` (C_xy is the
    ground-plane centre-of-mass velocity in m/s), rotated by ``confounding_strength * pi``
    in the deployment regime; the reward is ``-1`` per step minus
    ``0.1 * |U|`` (the episode ends at success).

    Model edits (documented deviations from TorchRL's MJX-tuned MJCF, which only lets the
    feet touch the floor): every body geom collides with the floor and the maze walls
    (else the humanoid would walk through walls), none with another body geom.

    Tasks: the ant's cells (medium (1, 1) → (6, 6), large (1, 1) → (7, 10)); the start
    is the standing pose at the cell centre plus uniform position noise of a quarter cell
    and uniform noise of 0.01 on the other coordinates (gymnasium's Humanoid); success
    within 0.45 m ends the episode; horizon 2000. A fallen humanoid does not end the
    episode (as in OGBench's HumanoidMaze).

    Examples:
        >>> env = HumanoidMazeEnv("medium", batch_size=2, seed=0)
        >>> td = env.rollout(3)
        >>> td["next", "E"].shape, td["next", "latent", "C"].shape, td["action"].shape
        (torch.Size([2, 3, 12]), torch.Size([2, 3, 3]), torch.Size([2, 3, 21]))
    """

    agent_xml: ClassVar[pathlib.Path] = pathlib.Path(torchrl.__file__).parent / "envs/custom/mujoco/assets/humanoid.xml"
    frame_skip: ClassVar[int] = 5
    variable_columns: ClassVar[Mapping[str, slice]] = {
        "P": slice(0, 2),
        "A": slice(7, _NQ),
        "H": slice(_HEAD, _HEAD + 1),
        "E": slice(_EXTREMITY, _EXTREMITY + 12),
        "V": slice(_VERTICAL, _VERTICAL + 3),
        "C": slice(_COM, _COM + 3),
        "J": slice(_NQ, _NQ + _NV),
    }
    state_width: ClassVar[int] = _COM + 3
    latent_variables: ClassVar[tuple[str, ...]] = ("C",)
    tasks: ClassVar[Mapping[str, MazeTask]] = {
        "medium": MazeTask("medium", start_cell=(1, 1), goal_cell=(6, 6)),
        "large": MazeTask("large", start_cell=(1, 1), goal_cell=(7, 10)),
    }
    default_horizon: ClassVar[int] = 2000
    qpos_noise: ClassVar[float] = 0.01
    qvel_noise_std: ClassVar[float] = 0.01

    @property
    def causal_template(self) -> TimeSliceTemplate:
        """The paper's slice graph (:data:`~torchrl_causal.envs.templates.HUMANOIDMAZE_TEMPLATE`)."""
        return HUMANOIDMAZE_TEMPLATE

    @classmethod
    def _edit_spec(cls, spec: mujoco.MjSpec) -> None:
        for pair in list(spec.pairs):  # the feet-only floor contacts, superseded below
            spec.delete(pair)
        for geom in spec.geoms:
            if geom.parent.name != "world":
                geom.contype, geom.conaffinity = _BODY_CONTYPE, _BODY_CONAFFINITY

    def _bind_model(self, model: mujoco.MjModel) -> None:
        self._head_id = model.body("head").id
        self._extremity_ids = [model.body(name).id for name in _EXTREMITIES]

    def _read_state(self, data: mujoco.MjData, row: np.ndarray) -> None:
        model, torso = self.simulator.model, self.simulator.torso_id
        # mj_step leaves positions-dependent quantities one substep behind qpos; recompute
        # them (and the subtree velocities) so that every variable describes the same state.
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        mujoco.mj_subtreeVel(model, data)
        row[:_NQ] = data.qpos
        row[_NQ:_HEAD] = data.qvel
        row[_HEAD] = data.xpos[self._head_id, 2]
        frame = data.xmat[torso].reshape(3, 3)
        row[_EXTREMITY:_VERTICAL] = ((data.xpos[self._extremity_ids] - data.xpos[torso]) @ frame).ravel()
        row[_VERTICAL:_COM] = frame[2]
        row[_COM:] = data.subtree_linvel[torso]

    def _sensor_signal(self, state: np.ndarray) -> np.ndarray:
        return state[:, _COM : _COM + 2]

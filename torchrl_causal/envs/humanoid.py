"""The paper's humanoid: OGBench's own model, its observation readout and a standing start.

The paper's HumanoidMaze is OGBench's ``humanoidmaze-{medium,large}-navigate``, whose agent is
DeepMind's dm_control humanoid as OGBench ships it (``ogbench/locomaze/assets/humanoid.xml``,
MIT; 21 motors, 0.005 s Euler steps, 100 solver iterations, ``hip_y`` ranges -110 / -120..20
with stiffness 20, every body geom colliding with the floor, the walls and the other body
geoms). :data:`HUMANOID_XML` is that file, read from the installed ``ogbench`` package, not a
copy; ``tests/test_humanoid.py`` steps OGBench's own maze env and ours side by side.

:func:`read_humanoid_variables` is OGBench's ``HumanoidEnv.get_ob`` written into a variable
buffer (the paper's P, A, H, E, V, C, J); :func:`standing_qpos` is the standing start shared by
the maze and the locomotion skill's open ground; :class:`HumanoidLocomotionEnv` is that skill's
open-ground task.
"""

from __future__ import annotations

import importlib.util
import math
import pathlib
from collections.abc import Sequence

import mujoco
import numpy as np
import torch
from ogbench.online_locomotion.humanoid import tolerance

from torchrl_causal.envs.base import GustProcess
from torchrl_causal.envs.mujoco_maze import BatchedSimulation
from torchrl_causal.envs.open_ground import DirectionalLocomotionEnv
from torchrl_causal.errors import InvalidValueError, MissingDependencyError

__all__ = [
    "COMMAND_FRAME_VECTORS",
    "HUMANOID_COLUMNS",
    "HUMANOID_SKILL_OBSERVATION_DIM",
    "HUMANOID_SKILL_VARIABLES",
    "HumanoidLocomotionEnv",
    "START_QPOS_NOISE",
    "START_QVEL_NOISE",
    "stand_reward",
    "HUMANOID_EXTREMITIES",
    "HUMANOID_FRAME_SKIP",
    "HUMANOID_STATE_WIDTH",
    "HUMANOID_XML",
    "HumanoidReadout",
    "standing_qpos",
]


def _ogbench_asset(name: str) -> pathlib.Path:
    spec = importlib.util.find_spec("ogbench")  # locates the package without importing it
    if spec is None or not spec.submodule_search_locations:
        raise MissingDependencyError("HumanoidMaze uses OGBench's humanoid model: `pip install ogbench` (MIT, no jax)")
    return pathlib.Path(next(iter(spec.submodule_search_locations))) / "locomaze" / "assets" / name


#: OGBench's humanoid MJCF (the installed ``ogbench`` package's own file).
HUMANOID_XML = _ogbench_asset("humanoid.xml")
#: Physics steps per control step (OGBench's ``HumanoidEnv``: 5 x 0.005 s, so 40 Hz control).
HUMANOID_FRAME_SKIP = 5
#: OGBench's extremities, in its order (left hand, left foot, right hand, right foot).
HUMANOID_EXTREMITIES = ("left_hand", "left_foot", "right_hand", "right_foot")

_NQ, _NV = 28, 27  # free joint (7 / 6) + 21 hinges
_HEAD, _EXTREMITY, _VERTICAL, _COM = _NQ + _NV, _NQ + _NV + 1, _NQ + _NV + 13, _NQ + _NV + 16
#: Variable -> columns of the buffer that :class:`HumanoidReadout` fills:
#: qpos (28) | qvel (27) | head height (1) | extremities (12) | torso vertical (3) | CoM velocity (3).
HUMANOID_COLUMNS = {
    "P": slice(0, 2),
    "A": slice(7, _NQ),
    "H": slice(_HEAD, _HEAD + 1),
    "E": slice(_EXTREMITY, _EXTREMITY + 12),
    "V": slice(_VERTICAL, _VERTICAL + 3),
    "C": slice(_COM, _COM + 3),
    "J": slice(_NQ, _NQ + _NV),
}
HUMANOID_STATE_WIDTH = _COM + 3
#: The standing start's noise — uniform half-width on qpos, standard deviation of qvel.
START_QPOS_NOISE = 0.01
START_QVEL_NOISE = 0.01


class HumanoidReadout:
    """Reads OGBench's humanoid observation into a float64 row laid out as :data:`HUMANOID_COLUMNS`.

    The values are OGBench's ``HumanoidEnv.get_ob`` (torso xy, hinge angles, head height,
    extremities in the torso frame, torso vertical, ``torso_subtreelinvel``, ``qvel``), computed
    from the state after the step: ``mj_step`` leaves positions-dependent quantities one
    substep behind ``qpos``, so the kinematics and subtree velocities are recomputed (OGBench
    runs ``mj_step1`` for the same reason).

    Examples:
        >>> model = mujoco.MjModel.from_xml_path(str(HUMANOID_XML))
        >>> data = mujoco.MjData(model)
        >>> row = np.zeros(HUMANOID_STATE_WIDTH)
        >>> HumanoidReadout(model).read(data, row)
        >>> round(float(row[HUMANOID_COLUMNS["H"]][0]), 2)  # qpos0: the torso at 1.5 m, the head 0.19 m above
        1.69
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.torso = model.body("torso").id
        self.head = model.body("head").id
        self.extremities = [model.body(name).id for name in HUMANOID_EXTREMITIES]

    def read(self, data: mujoco.MjData, row: np.ndarray) -> None:
        model, torso = self.model, self.torso
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        mujoco.mj_subtreeVel(model, data)
        row[:_NQ] = data.qpos
        row[_NQ:_HEAD] = data.qvel
        row[_HEAD] = data.xpos[self.head, 2]
        frame = data.xmat[torso].reshape(3, 3)
        row[_EXTREMITY:_VERTICAL] = ((data.xpos[self.extremities] - data.xpos[torso]) @ frame).ravel()
        row[_VERTICAL:_COM] = frame[2]
        row[_COM:] = data.subtree_linvel[torso]


def standing_qpos(model: mujoco.MjModel, yaw: np.ndarray, *, clearance: float = 0.0) -> np.ndarray:
    """``(n, nq)`` standing poses: ``qpos0`` (legs straight, arms down) turned by ``yaw``, feet on the floor.

    OGBench's own reset drops the humanoid from 1.5 m in a random orientation with random
    joint angles, so it starts lying down; a maze expert built from a walking skill needs a
    standing start instead, which this is: the lowest body point ``clearance`` metres above the floor.

    Examples:
        >>> model = mujoco.MjModel.from_xml_path(str(HUMANOID_XML))
        >>> qpos = standing_qpos(model, np.array([0.0, np.pi]))
        >>> qpos[:, 2].round(3).tolist(), qpos[1, 3:7].round(6).tolist()
        ([1.285, 1.285], [0.0, 0.0, 0.0, 1.0])
    """
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    body_geoms = model.geom_bodyid > 0
    # Capsules and spheres (every body geom of the humanoid): the lowest point is centre - radius.
    lowest = float(np.min(data.geom_xpos[body_geoms, 2] - model.geom_size[body_geoms, 0]))
    yaw = np.asarray(yaw, dtype=np.float64)
    qpos = np.tile(model.qpos0, (yaw.size, 1))
    qpos[:, 2] += clearance - lowest
    qpos[:, 3:7] = np.stack((np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)), axis=-1)
    return qpos


#: The skill's variables, in OGBench's skill-observation order (its ``online-humanoid`` ``_get_obs``):
#: everything the maze expert reads except the position P, so the skill is translation-invariant.
HUMANOID_SKILL_VARIABLES = ("A", "H", "E", "V", "C", "J")
#: The skill's observation — those 67 dims and the commanded unit direction (2).
HUMANOID_SKILL_OBSERVATION_DIM = 67 + 2
_SKILL_COLUMNS = np.concatenate([np.arange(HUMANOID_STATE_WIDTH)[HUMANOID_COLUMNS[v]] for v in HUMANOID_SKILL_VARIABLES])
_COMMAND = HUMANOID_SKILL_OBSERVATION_DIM - 2
#: Where the skill observation's world-frame ground-plane vectors start — C's x, y (the
#: centre-of-mass velocity), ``qvel``'s first two (the root's linear velocity, world frame for a
#: free joint) and the command; the rest of the observation is egocentric or yaw-free.
COMMAND_FRAME_VECTORS = (int(np.flatnonzero(_SKILL_COLUMNS == _COM)[0]), int(np.flatnonzero(_SKILL_COLUMNS == _NQ)[0]), _COMMAND)


class HumanoidLocomotionEnv(DirectionalLocomotionEnv):
    """OGBench's humanoid walking along a commanded direction in open ground, shaken by tremors.

    The issue-38 skill task, shaped on OGBench's own humanoid skill (``DMCHumanoidXYWrapper``):

    * observation (69): the expert's variables without P (:data:`HUMANOID_SKILL_VARIABLES`:
      hinge angles, head height, extremities, torso vertical, centre-of-mass velocity C, ``qvel``),
      then the command, OGBench's order; never the vibration sensor W;
    * reward ``stand * (1 + speed_weight * min(speed, speed_cap))``, ``stand`` dm_control's (head at
      1.4 m or above, margin 0.35, times torso uprightness) and ``speed`` the torso's ground-plane
      velocity along the command in m/s (OGBench: ``1 + 2.5 speed``, uncapped);
    * start standing (:func:`standing_qpos`, uniform yaw, the maze's noise); terminate when the head
      drops below ``fall_height`` (OGBench starts fallen and never terminates: the standing start
      and the termination are what make the skill affordable here);
    * command redrawn every 100-200 steps (uniform), the maze's tremor process on the torso.

    Args:
        batch_size: number of independent simulations (one dimension).
        horizon: steps before truncation.
        direction_period: steps between redraws, or an inclusive ``(low, high)`` range.
        speed_cap: speed (m/s) beyond which walking faster earns nothing.
        speed_weight: the speed term's weight (1: standing earns half of walking at 1 m/s;
            OGBench's 2.5 makes walking pay more against standing still).
        command_spread: the largest angle between a new command and the torso's heading
            (:class:`~torchrl_causal.envs.open_ground.DirectionalLocomotionEnv`; ``pi``: uniform).
        fall_height: head height (m) below which the episode terminates.
        gust_process: the tremor (the maze suite's by default).
        seed: seed of the env's generator.

    Examples:
        >>> env = HumanoidLocomotionEnv(batch_size=2, seed=0)
        >>> td = env.rollout(3)
        >>> td["observation"].shape, td["next", "speed"].shape
        (torch.Size([2, 3, 69]), torch.Size([2, 3, 1]))
    """

    def __init__(
        self,
        batch_size: int | Sequence[int] = 1,
        *,
        horizon: int = 1000,
        direction_period: int | tuple[int, int] = (100, 200),
        speed_cap: float = 1.5,
        speed_weight: float = 1.0,
        command_spread: float = math.pi,
        fall_height: float = 0.9,
        gust_process: GustProcess | None = None,
        seed: int | None = None,
    ) -> None:
        count = self.batch_count(batch_size)
        if not speed_cap > 0 or not fall_height > 0 or not speed_weight >= 0:
            raise InvalidValueError(
                f"speed_cap and fall_height must be > 0 and speed_weight >= 0, got {speed_cap}, {fall_height}, {speed_weight}"
            )
        self.speed_cap, self.speed_weight, self.fall_height = float(speed_cap), float(speed_weight), float(fall_height)
        model = mujoco.MjModel.from_xml_path(str(HUMANOID_XML))
        self._readout = HumanoidReadout(model)
        self._variables = np.zeros((count, HUMANOID_STATE_WIDTH))
        self._read_after_step = False
        super().__init__(
            BatchedSimulation(model, num_envs=count, frame_skip=HUMANOID_FRAME_SKIP),
            observation_dim=HUMANOID_SKILL_OBSERVATION_DIM,
            horizon=horizon,
            direction_period=direction_period,
            gust_process=gust_process,
            seed=seed,
            command_spread=command_spread,
        )

    def _start_state(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        model = self.simulation.model
        yaw = 2 * np.pi * torch.rand(count, generator=self.rng, dtype=torch.float64).numpy()
        uniform = torch.rand(count, model.nq, generator=self.rng, dtype=torch.float64).numpy() * 2 - 1
        gaussian = torch.randn(count, model.nv, generator=self.rng, dtype=torch.float64).numpy()
        qpos = standing_qpos(model, yaw, clearance=START_QPOS_NOISE) + START_QPOS_NOISE * uniform
        return qpos, START_QVEL_NOISE * gaussian

    def _read(self, qpos: np.ndarray) -> torch.Tensor:
        if not self._read_after_step:  # a reset moved some simulations since
            self._read_all()
        self._read_after_step = False
        return torch.from_numpy(self._variables[:, _SKILL_COLUMNS]).float()

    def _read_all(self) -> None:
        for data, row in zip(self.simulation.datas, self._variables):
            self._readout.read(data, row)

    def _reward_and_fall(self, speed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        # Read the state after this step once: the observation that follows reuses it
        # (the readout is a fifth of a step's cost at 64 simulations).
        self._read_all()
        self._read_after_step = True
        head = self._variables[:, HUMANOID_COLUMNS["H"]]
        upright = self._variables[:, HUMANOID_COLUMNS["V"]][:, 2:]
        stand = torch.from_numpy(stand_reward(head, upright)).float()
        reward = stand * (1 + self.speed_weight * speed.clamp(max=self.speed_cap))
        return reward, torch.from_numpy(head < self.fall_height)


def stand_reward(head_height: np.ndarray, torso_upright: np.ndarray) -> np.ndarray:
    """dm_control's humanoid ``standing * upright`` in ``[0, 1]`` (OGBench's skill reward's factor).

    ``standing`` is 1 with the head at 1.4 m or above and decays as a Gaussian with 0.1 at
    0.35 m below; ``upright`` (the torso's z-axis world component) is 1 above 0.9, falling
    linearly to 0 at -1.

    Examples:
        >>> stand_reward(np.array([1.5, 1.05, 1.5]), np.array([1.0, 1.0, -1.0])).round(3).tolist()
        [1.0, 0.1, 0.0]
    """
    standing = tolerance(head_height, bounds=(1.4, float("inf")), margin=1.4 / 4)
    upright = tolerance(torso_upright, bounds=(0.9, float("inf")), margin=1.9, sigmoid="linear", value_at_margin=0)
    return standing * upright

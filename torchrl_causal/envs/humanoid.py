"""The paper's humanoid: OGBench's own model, its observation readout and a standing start.

The paper's HumanoidMaze is OGBench's ``humanoidmaze-{medium,large}-navigate``, whose agent is
DeepMind's dm_control humanoid as OGBench ships it (``ogbench/locomaze/assets/humanoid.xml``,
MIT; 21 motors, 0.005 s Euler steps, 100 solver iterations, ``hip_y`` ranges -110 / -120..20
with stiffness 20, every body geom colliding with the floor, the walls and the other body
geoms). :data:`HUMANOID_XML` is that file, read from the installed ``ogbench`` package, not a
copy; ``tests/test_humanoid.py`` steps OGBench's own maze env and ours side by side.

:func:`read_humanoid_variables` is OGBench's ``HumanoidEnv.get_ob`` written into a variable
buffer (the paper's P, A, H, E, V, C, J); :func:`standing_qpos` is the standing start shared by
the maze and the locomotion skill's open ground.
"""

from __future__ import annotations

import importlib.util
import pathlib

import mujoco
import numpy as np

__all__ = [
    "HUMANOID_COLUMNS",
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
        raise ModuleNotFoundError("HumanoidMaze uses OGBench's humanoid model: `pip install ogbench` (MIT, no jax)")
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


"""The paper's ant: OGBench's physics on gymnasium's ant model, and its locomotion skill.

The paper's mazes are OGBench's ``antmaze-{medium,large}-navigate``. OGBench's ant has
gymnasium's geometry, masses and joint ranges but different physics:
:func:`ogbench_ant_physics` applies exactly those differences through :class:`mujoco.MjSpec`
(0.02 s RK4 steps, 5 per control step so 10 Hz control; actuator gear 30 instead of 150;
contact ``solref=".02 1"`` ``solimp=".8 .8 .01"`` on every geom, floor and walls included).
Gymnasium's 20 Hz, gear-150 ant flips under random actions and barely feels a gust.

:class:`AntLocomotionEnv` is the open-ground task OGBench's maze experts were trained on: walk
along a commanded unit direction (redrawn every 100 steps) while the maze suite's gust
process pushes the torso. The skill's policy body and its shipped weights are the experts'
(:mod:`torchrl_causal.experts.skills`), trained by :mod:`torchrl_causal.experts.locomotion`.
"""

from __future__ import annotations

import pathlib
from collections.abc import Sequence

import gymnasium
import mujoco
import numpy as np
import torch

from torchrl_causal.envs.base import GustProcess
from torchrl_causal.envs.mujoco_maze import BatchedSimulation
from torchrl_causal.envs.open_ground import DirectionalLocomotionEnv

__all__ = [
    "ANT_XML",
    "LOCOMOTION_ACTION_DIM",
    "LOCOMOTION_OBSERVATION_DIM",
    "AntLocomotionEnv",
    "locomotion_observation",
    "ogbench_ant_physics",
]

#: gymnasium's ant MJCF (geometry, masses and joint ranges shared with OGBench's ant).
ANT_XML = pathlib.Path(gymnasium.__file__).parent / "envs/mujoco/assets/ant.xml"

#: OGBench's ant: physics step (s), physics steps per control step, actuator gear, contact.
OGBENCH_TIMESTEP = 0.02
OGBENCH_FRAME_SKIP = 5
OGBENCH_GEAR = 30.0
OGBENCH_SOLREF = (0.02, 1.0)
OGBENCH_SOLIMP = (0.8, 0.8, 0.01, 0.5, 2.0)  # MJCF ".8 .8 .01" leaves MuJoCo's width/midpoint/power
#: OGBench's reset noise: uniform half-width on qpos, standard deviation on qvel.
OGBENCH_QPOS_NOISE = 0.1
OGBENCH_QVEL_NOISE = 0.1

_NQ, _NV, _NU = 15, 14, 8
#: qpos[2:] (13), qvel (14) and the commanded unit direction (2).
LOCOMOTION_OBSERVATION_DIM = _NQ - 2 + _NV + 2
#: The 8 hinge torques.
LOCOMOTION_ACTION_DIM = _NU


def ogbench_ant_physics(spec: mujoco.MjSpec) -> None:
    """Gives an ant model OGBench's physics, in place (before ``spec.compile()``).

    Reference: OGBench (Park et al., 2024), ``locomaze/assets/ant.xml``: ``timestep 0.02``
    with RK4, motor ``gear 30``, and ``solref=".02 1" solimp=".8 .8 .01"`` on every geom.

    Examples:
        >>> spec = mujoco.MjSpec.from_file(str(ANT_XML))
        >>> ogbench_ant_physics(spec)
        >>> model = spec.compile()
        >>> model.opt.timestep, model.actuator_gear[:, 0].tolist() == [30.0] * 8
        (0.02, True)
        >>> model.geom_solimp[0, :3].tolist(), model.geom_solref[0].tolist()
        ([0.8, 0.8, 0.01], [0.02, 1.0])
    """
    spec.option.timestep = OGBENCH_TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_RK4
    for actuator in spec.actuators:
        gear = np.zeros(6)
        gear[0] = OGBENCH_GEAR
        actuator.gear = gear
    for geom in spec.geoms:
        geom.solref = list(OGBENCH_SOLREF)
        geom.solimp = list(OGBENCH_SOLIMP)


def locomotion_observation(qpos_tail: torch.Tensor, qvel: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
    """The locomotion policy's input: ``qpos[2:]`` (height, orientation, hinges), ``qvel``, direction."""
    return torch.cat((qpos_tail, qvel, direction), dim=-1)


class AntLocomotionEnv(DirectionalLocomotionEnv):
    """OGBench's ant walking along a commanded direction in open ground, in the wind.

    Observation ``"observation"``: ``qpos[2:]`` (torso height, orientation quaternion, 8
    hinge angles), ``qvel`` (14) and the commanded unit direction (2), 29 dims; the xy
    position is left out, so the skill is translation-invariant. ``"action"``: the 8
    torques in ``[-1, 1]``. Reward: the torso's xy velocity along the direction
    (displacement per control step / 0.1 s, m/s). The direction is redrawn uniformly every
    ``direction_period`` steps; the maze suite's :class:`~torchrl_causal.envs.GustProcess`
    pushes the torso (newtons, redrawn every 5 steps). Episodes terminate when the torso
    leaves ``z in [0.2, 1]`` and are truncated at ``horizon``. Resets add OGBench's noise
    (uniform 0.1 on qpos, N(0, 0.1²) on qvel). The rest is
    :class:`~torchrl_causal.envs.open_ground.DirectionalLocomotionEnv`'s.

    Args:
        batch_size: number of independent simulations (one dimension).
        horizon: steps before truncation.
        direction_period: steps between direction redraws.
        gust_process: the wind (the maze suite's by default; ``GustProcess(probability=0)`` for calm).
        seed: seed of the env's generator.

    Examples:
        >>> env = AntLocomotionEnv(batch_size=2, seed=0)
        >>> td = env.rollout(3)
        >>> td["observation"].shape, td["next", "reward"].shape
        (torch.Size([2, 3, 29]), torch.Size([2, 3, 1]))
    """

    def __init__(
        self,
        batch_size: int | Sequence[int] = 1,
        *,
        horizon: int = 1000,
        direction_period: int = 100,
        gust_process: GustProcess | None = None,
        seed: int | None = None,
    ) -> None:
        count = self.batch_count(batch_size)
        spec = mujoco.MjSpec.from_file(str(ANT_XML))
        ogbench_ant_physics(spec)
        super().__init__(
            BatchedSimulation(spec.compile(), num_envs=count, frame_skip=OGBENCH_FRAME_SKIP),
            observation_dim=LOCOMOTION_OBSERVATION_DIM,
            horizon=horizon,
            direction_period=direction_period,
            gust_process=gust_process,
            seed=seed,
        )

    def _start_state(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        model = self.simulation.model
        uniform = torch.rand(count, model.nq, generator=self.rng, dtype=torch.float64) * 2 - 1
        gaussian = torch.randn(count, model.nv, generator=self.rng, dtype=torch.float64)
        return model.qpos0 + OGBENCH_QPOS_NOISE * uniform.numpy(), OGBENCH_QVEL_NOISE * gaussian.numpy()

    def _read(self, qpos: np.ndarray) -> torch.Tensor:
        return torch.cat((torch.from_numpy(qpos[:, 2:]), torch.from_numpy(self.simulation.qvel())), dim=-1).float()

    def _reward_and_fall(self, speed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        height = torch.from_numpy(self.simulation.qpos()[:, 2:3]).float()
        return speed, (height < 0.2) | (height > 1.0)

"""Policies and programs about the envs: the maze planner, the experts, the walking skills and their trainers.

* :mod:`~torchrl_causal.experts.planner`: :class:`MazePlanner`, shortest-path waypoints over a
  :class:`~torchrl_causal.envs.MazeLayout`;
* :mod:`~torchrl_causal.experts.policies`: the experts the demonstrations come from, TorchRL
  policies that read the latent state the imitator does not (:class:`RoverExpert`,
  :class:`AntMazeExpert`, :class:`HumanoidMazeExpert`, :class:`RouteChoiceExpert`);
* :mod:`~torchrl_causal.experts.skills`: the walking skills' policy bodies and shipped weights,
  which the MuJoCo maze experts steer;
* :mod:`~torchrl_causal.experts.locomotion` (SAC, the ant's) and
  :mod:`~torchrl_causal.experts.locomotion_ppo` (PPO, the humanoid's): the skills' trainers,
  command lines that checkpoint with :mod:`torchrl_causal.experiment`'s run-directory helpers.

This package stands above :mod:`torchrl_causal.envs` (which never imports it) and
:mod:`torchrl_causal.experiment`. The names below load their module on first use, as
:mod:`torchrl_causal.envs`' do.
"""

from importlib import import_module

_EXPORTS = {
    "AntMazeExpert": "policies",
    "CommandFrame": "skills",
    "HumanoidMazeExpert": "policies",
    "MazePlanner": "planner",
    "RouteChoiceExpert": "policies",
    "RoverExpert": "policies",
    "load_humanoid_locomotion_network": "skills",
    "load_locomotion_network": "skills",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})

"""Confounded envs as TorchRL envs: the SCM base, Route Choice, RoverMaze, planners and experts.

Every env exposes ``causal_template``, ``regime`` (``"train"`` | ``"deploy"``),
``confounding_strength`` in ``[0, 1]`` and ``horizon``; observed variables are root keys,
variables latent to the imitator live under ``("latent", name)`` and the confounder under
``("scm", name)``.

The names below load their module on first use, so that ``torchrl_causal.envs.templates``
(pure data) imports without torch or MuJoCo.
"""

from importlib import import_module

_EXPORTS = {
    "AntLocomotionEnv": "ant",
    "AntMazeEnv": "antmaze",
    "AntMazeExpert": "torchrl_causal.experts.policies",
    "CompassSensor": "base",
    "ConfoundedEnv": "base",
    "GustConfoundedEnv": "base",
    "GustProcess": "base",
    "HumanoidMazeEnv": "humanoidmaze",
    "HumanoidMazeExpert": "torchrl_causal.experts.policies",
    "MAZE_MAPS": "maze_layout",
    "MazeLayout": "maze_layout",
    "MazePlanner": "torchrl_causal.experts.planner",
    "REGIMES": "base",
    "ROVER_TASKS": "rover_maze",
    "RouteChoiceEnv": "route_choice",
    "RouteChoiceExpert": "torchrl_causal.experts.policies",
    "RoverExpert": "torchrl_causal.experts.policies",
    "RoverMazeEnv": "rover_maze",
    "RoverParameters": "rover_maze",
    "rotate": "base",
    "route_choice_value": "route_choice",
    "rover_dynamics": "rover_maze",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(module if "." in module else f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})

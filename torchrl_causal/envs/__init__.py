"""Confounded envs as TorchRL envs: the SCM base, Route Choice, RoverMaze and the MuJoCo mazes.

Every env exposes ``causal_template``, ``regime`` (``"train"`` | ``"deploy"``),
``confounding_strength`` in ``[0, 1]`` and ``horizon``; observed variables are root keys,
variables latent to the imitator live under ``("latent", name)`` and the confounder under
``("scm", name)``. The policies and programs about these envs (the planner, the experts, the
walking skills and their trainers) are :mod:`torchrl_causal.experts`.

The names below load their module on first use, so that ``torchrl_causal.envs.templates``
(pure data) imports without torch or MuJoCo.
"""

from importlib import import_module

_EXPORTS = {
    "AntLocomotionEnv": "ant",
    "AntMazeEnv": "antmaze",
    "CompassSensor": "base",
    "ConfoundedEnv": "base",
    "GustConfoundedEnv": "base",
    "GustProcess": "base",
    "HumanoidMazeEnv": "humanoidmaze",
    "MAZE_MAPS": "maze_layout",
    "MazeLayout": "maze_layout",
    "REGIMES": "base",
    "ROVER_TASKS": "rover_maze",
    "RouteChoiceEnv": "route_choice",
    "RoverMazeEnv": "rover_maze",
    "RoverParameters": "rover_maze",
    "rotate": "base",
    "route_choice_value": "route_choice",
    "rover_dynamics": "rover_maze",
}

#: Names this package held before :mod:`torchrl_causal.experts` had them: archived run configs
#: name them (``_target_: torchrl_causal.envs.AntMazeExpert``), so they still resolve, only on
#: first use (importing ``envs`` never imports ``experts``, which stands above it). Not in
#: ``__all__``: new code imports them from :mod:`torchrl_causal.experts`.
MOVED_TO_EXPERTS = ("AntMazeExpert", "HumanoidMazeExpert", "MazePlanner", "RouteChoiceExpert", "RoverExpert")

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    if name in MOVED_TO_EXPERTS:
        value = getattr(import_module("torchrl_causal.experts"), name)
    elif name in _EXPORTS:
        value = getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})

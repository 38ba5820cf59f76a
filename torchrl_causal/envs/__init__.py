"""Confounded envs as TorchRL envs: the SCM base, Route Choice, RoverMaze, planners and experts.

Every env exposes ``causal_template``, ``regime`` (``"train"`` | ``"deploy"``),
``confounding_strength`` in ``[0, 1]`` and ``horizon``; observed variables are root keys,
variables latent to the imitator live under ``("latent", name)`` and the confounder under
``("scm", name)``.
"""

from torchrl_causal.envs.antmaze import AntMazeEnv
from torchrl_causal.envs.base import (
    REGIMES,
    CompassSensor,
    ConfoundedEnv,
    GustConfoundedEnv,
    GustProcess,
    rotate,
)
from torchrl_causal.envs.ant import AntLocomotionEnv
from torchrl_causal.envs.experts import AntMazeExpert, RouteChoiceExpert, RoverExpert
from torchrl_causal.envs.humanoidmaze import HumanoidMazeEnv
from torchrl_causal.envs.planner import MAZE_MAPS, MazeLayout, MazePlanner
from torchrl_causal.envs.route_choice import RouteChoiceEnv, route_choice_value
from torchrl_causal.envs.rover_maze import ROVER_TASKS, RoverMazeEnv, RoverParameters, rover_dynamics

__all__ = [
    "MAZE_MAPS",
    "REGIMES",
    "ROVER_TASKS",
    "AntLocomotionEnv",
    "AntMazeEnv",
    "AntMazeExpert",
    "CompassSensor",
    "ConfoundedEnv",
    "GustConfoundedEnv",
    "GustProcess",
    "HumanoidMazeEnv",
    "MazeLayout",
    "MazePlanner",
    "RouteChoiceEnv",
    "RouteChoiceExpert",
    "RoverExpert",
    "RoverMazeEnv",
    "RoverParameters",
    "rotate",
    "route_choice_value",
    "rover_dynamics",
]

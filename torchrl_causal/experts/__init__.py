"""Policies and programs about the envs: the maze planner, the experts and the walking skills' trainers.

The names below load their module on first use, as :mod:`torchrl_causal.envs`' do.
"""

from importlib import import_module

_EXPORTS = {
    "AntMazeExpert": "policies",
    "HumanoidMazeExpert": "policies",
    "MazePlanner": "planner",
    "RouteChoiceExpert": "policies",
    "RoverExpert": "policies",
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

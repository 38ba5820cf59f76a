"""Old path of :class:`~torchrl_causal.experts.MazePlanner` and of the maze geometry
(:mod:`torchrl_causal.envs.maze_layout`), kept for code written against it; nothing in the package imports it."""

from torchrl_causal.envs.maze_layout import MAZE_MAPS, MazeLayout
from torchrl_causal.experts.planner import MazePlanner

__all__ = ["MAZE_MAPS", "MazeLayout", "MazePlanner"]

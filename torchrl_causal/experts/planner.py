"""The shortest-path waypoint planner shared by every maze expert.

:class:`MazePlanner` runs a breadth-first search from the goal over the free cells of a
:class:`~torchrl_causal.envs.maze_layout.MazeLayout` (a distance field), follows it from the
agent's cell, and returns as waypoint the furthest of the next ``lookahead`` path cells whose
centre is in clear line of sight (a box of half-size ``clearance`` swept along the segment
touches no wall). Everything is batched torch, in the layout's world coordinates, so the MuJoCo
mazes and RoverMaze share one planner.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import torch

from torchrl_causal.envs.maze_layout import MazeLayout
from torchrl_causal.errors import InvalidValueError

__all__ = ["MazePlanner"]

_NEIGHBOURS = ((-1, 0), (1, 0), (0, -1), (0, 1))


class MazePlanner:
    """Shortest-path waypoints to a goal cell over a :class:`~torchrl_causal.envs.maze_layout.MazeLayout` (batched).

    Args:
        layout: the maze.
        goal_cell: ``(row, col)`` of the goal; must be free.
        lookahead: how many path cells ahead a waypoint may be.
        clearance: half-size (world units) of the box that must pass a line of sight.
        sight_samples: points checked along each line of sight.

    Examples:
        >>> layout = MazeLayout.from_name("u")
        >>> planner = MazePlanner(layout, goal_cell=(3, 1))
        >>> planner.distance[1, 1].item()  # the U: east 2, south 2, west 2
        6
        >>> start = layout.cell_center(torch.tensor([[1, 1]]))
        >>> layout.cell_of(planner.waypoint(start)).tolist()  # straight east along the top corridor
        [[1, 3]]
    """

    def __init__(
        self,
        layout: MazeLayout,
        goal_cell: Sequence[int],
        *,
        lookahead: int = 6,
        clearance: float | None = None,
        sight_samples: int = 32,
    ) -> None:
        goal = (int(goal_cell[0]), int(goal_cell[1]))
        if not layout.is_free_cell(goal):
            raise InvalidValueError(f"goal_cell {goal} is not a free cell of the maze")
        if lookahead < 1 or sight_samples < 2:
            raise InvalidValueError(f"lookahead must be >= 1 and sight_samples >= 2, got {lookahead}, {sight_samples}")
        self.layout = layout
        self.goal_cell = goal
        self.lookahead = lookahead
        self.clearance = 0.15 * layout.cell_size if clearance is None else float(clearance)
        self.sight_samples = sight_samples
        self.distance = self._distance_field(goal)
        self._next_cell = self._descent_table()

    def _distance_field(self, goal: tuple[int, int]) -> torch.Tensor:
        """BFS distance (in cells, 4-connected) to ``goal``; -1 on walls and unreachable cells."""
        distance = torch.full(self.layout.shape, -1, dtype=torch.long)
        distance[goal] = 0
        frontier = deque([goal])
        while frontier:
            row, col = frontier.popleft()
            for d_row, d_col in _NEIGHBOURS:
                cell = (row + d_row, col + d_col)
                if self.layout.is_free_cell(cell) and distance[cell] < 0:
                    distance[cell] = distance[row, col] + 1
                    frontier.append(cell)
        return distance

    def _descent_table(self) -> torch.Tensor:
        """Flat index of the next cell towards the goal for every cell (itself at the goal or off-path)."""
        rows, cols = self.layout.shape
        table = torch.arange(rows * cols)
        for row, col in self.layout.free_cells():
            here = int(self.distance[row, col])
            for d_row, d_col in _NEIGHBOURS:
                cell = (row + d_row, col + d_col)
                if here > 0 and self.layout.is_free_cell(cell) and int(self.distance[cell]) == here - 1:
                    table[row * cols + col] = cell[0] * cols + cell[1]
                    break
        return table

    def path_cells(self, xy: torch.Tensor) -> torch.Tensor:
        """The agent's cell then the next ``lookahead`` cells towards the goal, ``... x (lookahead+1) x 2``."""
        cols = self.layout.shape[1]
        table = self._next_cell.to(xy.device)
        flat = self.layout.flat_index(self.layout.cell_of(xy))
        path = [flat]
        for _ in range(self.lookahead):
            path.append(table[path[-1]])
        flat_path = torch.stack(path, dim=-1)
        return torch.stack((flat_path // cols, flat_path % cols), dim=-1)

    def in_sight(self, origin: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """Whether the clearance box can slide straight from ``origin`` (``... x 2``) to each target (``... x n x 2``).

        Conservative, never optimistic: every point of the segment lies within half a
        sample spacing (in each axis) of a sample, so boxes grown by that much at the
        samples cover the whole sweep.
        """
        fractions = torch.linspace(0.0, 1.0, self.sight_samples, device=origin.device)
        origin = origin.unsqueeze(-2)
        spacing = (targets - origin).abs().amax(-1) / (self.sight_samples - 1)
        points = origin.unsqueeze(-2) + (targets - origin).unsqueeze(-2) * fractions[:, None]
        half_size = (self.clearance + spacing / 2).clamp_max(0.499 * self.layout.cell_size)
        return self.layout.box_is_free(points, half_size[..., None]).all(-1)

    def waypoint(self, xy: torch.Tensor) -> torch.Tensor:
        """The world position to head for from each ``xy`` (``... x 2``).

        The centre of the furthest path cell (among the next ``lookahead``) in clear line of
        sight; the agent's own cell centre when none is, which is always reachable.
        """
        centers = self.layout.cell_center(self.path_cells(xy))
        visible = self.in_sight(xy, centers[..., 1:, :])
        steps = torch.arange(1, self.lookahead + 1, device=xy.device)
        furthest = torch.where(visible, steps, torch.zeros_like(steps)).amax(-1)
        return torch.gather(centers, -2, furthest[..., None, None].expand(*furthest.shape, 1, 2)).squeeze(-2)

    def cells_to_goal(self, xy: torch.Tensor) -> torch.Tensor:
        """BFS distance (cells) from each point's cell to the goal."""
        flat = self.layout.flat_index(self.layout.cell_of(xy))
        return self.distance.flatten().to(xy.device)[flat]

"""Maze geometry and the shortest-path waypoint planner shared by every maze expert.

:class:`MazeLayout` reads a gymnasium-robotics map (``1`` = wall) and uses its world
coordinates: with ``H x W`` cells of side ``s``, cell ``(row, col)`` is centred at
``x = (col + 0.5) * s - W * s / 2``, ``y = H * s / 2 - (row + 0.5) * s`` (rows grow
southwards, ``y`` grows northwards), exactly as ``gymnasium_robotics.envs.maze.Maze`` does,
so the MuJoCo mazes (``s = 4``) and RoverMaze (``s = 1``) share one planner.

:class:`MazePlanner` runs a breadth-first search from the goal over free cells (a distance
field), follows it from the agent's cell, and returns as waypoint the furthest of the next
``lookahead`` path cells whose centre is in clear line of sight (a box of half-size
``clearance`` swept along the segment touches no wall). Everything is batched torch.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import torch
from gymnasium_robotics.envs.maze import maps

__all__ = ["MAZE_MAPS", "MazeLayout", "MazePlanner"]

_NEIGHBOURS = ((-1, 0), (1, 0), (0, -1), (0, 1))


MAZE_MAPS: dict[str, list[list[int]]] = {"u": maps.U_MAZE, "medium": maps.MEDIUM_MAZE, "large": maps.LARGE_MAZE}


class MazeLayout:
    """A maze map as batched torch geometry: coordinates, cells and wall collisions.

    Args:
        maze_map: rows of cells; ``1`` is a wall, anything else (``0``, ``"g"``, ``"r"``...)
            is free. The border must be walls.
        cell_size: side of a cell in world units (gymnasium-robotics' ``maze_size_scaling``).

    Examples:
        >>> layout = MazeLayout.from_name("u")
        >>> layout.shape
        (5, 5)
        >>> layout.cell_center(torch.tensor([[1, 1]])).tolist()
        [[-1.0, 1.0]]
        >>> layout.cell_of(torch.tensor([[-1.2, 0.9]])).tolist()
        [[1, 1]]
        >>> layout.box_is_free(torch.tensor([[-1.0, 1.0], [-1.0, 0.0]]), half_size=0.1).tolist()
        [True, False]
    """

    def __init__(self, maze_map: Sequence[Sequence[int | str]], cell_size: float = 1.0) -> None:
        rows = [list(row) for row in maze_map]
        if not rows or any(len(row) != len(rows[0]) for row in rows):
            raise ValueError("maze_map must be a non-empty rectangular list of rows")
        walls = torch.tensor([[cell == 1 for cell in row] for row in rows], dtype=torch.bool)
        if not (walls[0].all() and walls[-1].all() and walls[:, 0].all() and walls[:, -1].all()):
            raise ValueError("maze_map must be enclosed by walls (1) on every border cell")
        if cell_size <= 0:
            raise ValueError(f"cell_size must be positive, got {cell_size}")
        self.walls = walls
        self.cell_size = float(cell_size)
        self._walls_flat = walls.flatten()

    @classmethod
    def from_name(cls, name: str, cell_size: float = 1.0) -> MazeLayout:
        """The gymnasium-robotics map ``"u"``, ``"medium"`` or ``"large"``."""
        if name not in MAZE_MAPS:
            raise ValueError(f"unknown maze {name!r}; expected one of {sorted(MAZE_MAPS)}")
        return cls(MAZE_MAPS[name], cell_size)

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the map."""
        rows, cols = self.walls.shape
        return rows, cols

    def is_free_cell(self, cell: Sequence[int]) -> bool:
        row, col = cell
        rows, cols = self.shape
        return 0 <= row < rows and 0 <= col < cols and not bool(self.walls[row, col])

    def free_cells(self) -> list[tuple[int, int]]:
        """Every free ``(row, col)``, row-major."""
        return [tuple(cell) for cell in (~self.walls).nonzero().tolist()]

    def _grid(self, xy: torch.Tensor) -> torch.Tensor:
        """Continuous ``(col, row)`` coordinates: cell ``(r, c)`` spans ``[c, c+1) x [r, r+1)``."""
        rows, cols = self.shape
        col = xy[..., 0] / self.cell_size + cols / 2
        row = rows / 2 - xy[..., 1] / self.cell_size
        return torch.stack((col, row), dim=-1)

    def cell_center(self, cells: torch.Tensor) -> torch.Tensor:
        """World ``(x, y)`` of the centre of integer ``(row, col)`` cells (``... x 2``)."""
        rows, cols = self.shape
        cells = cells.to(torch.float32)
        x = (cells[..., 1] + 0.5 - cols / 2) * self.cell_size
        y = (rows / 2 - cells[..., 0] - 0.5) * self.cell_size
        return torch.stack((x, y), dim=-1)

    def cell_of(self, xy: torch.Tensor) -> torch.Tensor:
        """Integer ``(row, col)`` of the cell containing each world point."""
        grid = self._grid(xy).floor().long()
        return grid.flip(-1)

    def flat_index(self, cells: torch.Tensor) -> torch.Tensor:
        return cells[..., 0] * self.shape[1] + cells[..., 1]

    def box_is_free(self, xy: torch.Tensor, half_size: float | torch.Tensor) -> torch.Tensor:
        """Whether an axis-aligned box of ``half_size`` (world units) centred at ``xy`` touches no wall.

        ``half_size`` (a float, or a tensor broadcastable to ``xy.shape[:-1]``) must be below
        half a cell, so the box spans at most 2 x 2 cells. Points outside the map count as
        blocked.
        """
        grid = self._grid(xy)
        half = torch.as_tensor(half_size, dtype=grid.dtype, device=grid.device)[..., None] / self.cell_size
        rows, cols = self.shape
        # The box may overlap the two cells on either side of each edge; checking the four
        # corner cells covers every cell it touches because it is less than one cell wide.
        low = (grid - half).floor().long()
        high = (grid + half).floor().long()
        inside = (low >= 0).all(-1) & (high[..., 0] < cols) & (high[..., 1] < rows)
        low, high = low.clamp_min(0), torch.stack((high[..., 0].clamp_max(cols - 1), high[..., 1].clamp_max(rows - 1)), -1)
        blocked = torch.zeros(xy.shape[:-1], dtype=torch.bool, device=xy.device)
        walls = self._walls_flat.to(xy.device)
        for col in (low[..., 0], high[..., 0]):
            for row in (low[..., 1], high[..., 1]):
                blocked = blocked | walls[row * cols + col]
        return inside & ~blocked


class MazePlanner:
    """Shortest-path waypoints to a goal cell over a :class:`MazeLayout` (batched).

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
            raise ValueError(f"goal_cell {goal} is not a free cell of the maze")
        if lookahead < 1 or sight_samples < 2:
            raise ValueError(f"lookahead must be >= 1 and sight_samples >= 2, got {lookahead}, {sight_samples}")
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

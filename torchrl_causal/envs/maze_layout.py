"""Maze geometry: the gymnasium-robotics maps as batched torch cells, coordinates and walls.

:class:`MazeLayout` reads a gymnasium-robotics map (``1`` = wall) and uses its world
coordinates: with ``H x W`` cells of side ``s``, cell ``(row, col)`` is centred at
``x = (col + 0.5) * s - W * s / 2``, ``y = H * s / 2 - (row + 0.5) * s`` (rows grow
southwards, ``y`` grows northwards), exactly as ``gymnasium_robotics.envs.maze.Maze`` does,
so the MuJoCo mazes (``s = 4``), RoverMaze (``s = 1``) and the experts' planner
(:class:`~torchrl_causal.experts.MazePlanner`) share one geometry.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from gymnasium_robotics.envs.maze import maps

from torchrl_causal.errors import InvalidValueError

__all__ = ["MAZE_MAPS", "MazeLayout"]


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
            raise InvalidValueError("maze_map must be a non-empty rectangular list of rows")
        walls = torch.tensor([[cell == 1 for cell in row] for row in rows], dtype=torch.bool)
        if not (walls[0].all() and walls[-1].all() and walls[:, 0].all() and walls[:, -1].all()):
            raise InvalidValueError("maze_map must be enclosed by walls (1) on every border cell")
        if cell_size <= 0:
            raise InvalidValueError(f"cell_size must be positive, got {cell_size}")
        self.walls = walls
        self.cell_size = float(cell_size)
        self._walls_flat = walls.flatten()

    @classmethod
    def from_name(cls, name: str, cell_size: float = 1.0) -> MazeLayout:
        """The gymnasium-robotics map ``"u"``, ``"medium"`` or ``"large"``."""
        if name not in MAZE_MAPS:
            raise InvalidValueError(f"unknown maze {name!r}; expected one of {sorted(MAZE_MAPS)}")
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

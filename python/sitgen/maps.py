"""Maps from files, and shortest paths on them.

:func:`load_map` reads ROS map_server YAML (+ its image), PNG/PGM, MovingAI ``.map`` (in the
core) and BARN grids (``.npy``, here with numpy). :func:`shortest_path` is the planner's A*.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.terrain import Grid

BARN_RESOLUTION_M = 0.15
"""BARN's cell size (Perille et al., 2020)."""


def load_map(
    path: str | Path,
    *,
    resolution: float = 0.1,
    unknown_free: bool = False,
    index: int | None = None,
) -> Grid:
    """Load a map as a :class:`Grid` (row 0 = top).

    - ``.yaml``/``.yml``: ROS map_server (image, resolution, negate, thresholds, origin, kept
      in ``Grid.origin``); unknown cells are occupied unless ``unknown_free``;
    - ``.png``/``.pgm``: ROS's default thresholds, at ``resolution`` m/cell;
    - ``.map``: MovingAI, at ``resolution`` m/cell;
    - ``.npy``: BARN grids (1 = obstacle), one 30 × 30 grid or a stack of them (pick with
      ``index``), at 0.15 m/cell, turned so that BARN's x (grid row) points east and its y
      (grid column) north.

    Raises OSError naming the file when it cannot be read or understood.
    """
    path = Path(path)
    if path.suffix.lower() == ".npy":
        return _load_barn(path, index)
    occupied, res, origin = _core.load_map(path, resolution, unknown_free)
    return Grid(occupied=occupied, resolution=res, origin=origin)


def _load_barn(path: Path, index: int | None) -> Grid:
    try:
        # Mapped, not read: the header's shape is checked before anything is allocated.
        mapped = np.load(path, allow_pickle=False, mmap_mode="r")
    except (OSError, ValueError) as e:
        raise OSError(f"cannot read {path}: {e}") from None
    if mapped.size > _core.MAX_CELLS:
        raise OSError(
            f"{path}: holds {mapped.size} cells, more than the {_core.MAX_CELLS} a map may have"
        )
    grids = np.asarray(mapped)
    if grids.ndim == 3:
        if index is None or not 0 <= index < grids.shape[0]:
            raise OSError(
                f"{path}: holds {grids.shape[0]} grids; give index in [0, {grids.shape[0]})"
            )
        grids = grids[index]
    if grids.ndim != 2:
        raise OSError(f"{path}: expected a 2-D grid or a stack of them, found shape {grids.shape}")
    # BARN cell (r, c) lies at x = x0 + 0.15 r, y = y0 + 0.15 c: rows run east, columns north.
    occupied = np.ascontiguousarray(np.rot90(grids != 0))
    return Grid(occupied=occupied, resolution=BARN_RESOLUTION_M)


def shortest_path(
    grid: Grid | npt.NDArray[np.bool_],
    start: tuple[int, int],
    goal: tuple[int, int],
) -> tuple[list[tuple[int, int]], float] | None:
    """A* with the MovingAI rules (8-connected, diagonal √2, no corner cutting) between cells
    given as (column, row) on a grid's occupied cells; returns (cells, length in cells), or
    None when there is no path."""
    blocked = grid.occupied if isinstance(grid, Grid) else grid
    return _core.shortest_path(np.ascontiguousarray(blocked, dtype=bool), start, goal)

"""Maps from files, and shortest paths on them.

:func:`load_map` reads ROS map_server YAML (+ its image), PNG/PGM, MovingAI ``.map`` (in the
core) and BARN grids (``.npy``, here with numpy). :func:`shortest_path` is the planner's A*.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.world.situation import Situation
from sitgen.world.terrain import Grid

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


BARN_WORLDS = 300
"""Worlds in the BARN benchmark."""


def barn_situation(data_dir: str | Path, index: int) -> Situation:
    """BARN world ``index`` (0-299) from the BARN data folder (``barn_grids_300x30x30.npy`` and
    ``barn_paths.txt``, as in ``../shared/data/barn``) as a situation: the world in its challenge
    course, a Jackal agent following the world's official path to the challenge's goal, no peers
    (the core's ``interchange::barn``). Raises OSError naming the file that is missing or
    malformed."""
    return BarnWorlds(data_dir).situation(index)


class BarnWorlds:
    """The BARN data folder, read once: each world as a situation on demand."""

    def __init__(self, data_dir: str | Path) -> None:
        data_dir = Path(data_dir)
        self.grids = _barn_grids(data_dir)
        self.paths = _barn_paths(data_dir)
        self.paths_file = data_dir / "barn_paths.txt"

    def situation(self, index: int) -> Situation:
        """World ``index`` (0-299) as a situation."""

        if not 0 <= index < BARN_WORLDS:
            raise _core.SpecError(f"index: {index} is not in [0, {BARN_WORLDS})")
        path = self.paths.get(index)
        if path is None:
            raise OSError(f"{self.paths_file}: no path for world {index}")
        grid = np.ascontiguousarray(self.grids[index] != 0, dtype=np.uint8)
        return Situation(_core.barn_situation(grid.tobytes(), path, index), check_start=False)


def _barn_grids(data_dir: Path) -> npt.NDArray[np.uint8]:
    file = data_dir / "barn_grids_300x30x30.npy"
    try:
        grids: npt.NDArray[np.uint8] = np.load(file, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise OSError(f"cannot read {file}: {e}") from None
    if grids.shape != (BARN_WORLDS, 30, 30):
        raise OSError(f"{file}: expected shape ({BARN_WORLDS}, 30, 30), found {grids.shape}")
    return grids


def _barn_paths(data_dir: Path) -> dict[int, list[tuple[int, int]]]:
    """``barn_paths.txt``: ``world N: r,c r,c …`` per line (``#`` comments)."""
    file = data_dir / "barn_paths.txt"
    try:
        text = file.read_text()
    except OSError as e:
        raise OSError(f"cannot read {file}: {e.strerror}") from None
    paths: dict[int, list[tuple[int, int]]] = {}
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        try:
            head, _, cells = line.partition(":")
            world = int(head.removeprefix("world").strip())
            paths[world] = [
                (int(r), int(c)) for r, c in (cell.split(",") for cell in cells.split())
            ]
        except ValueError:
            raise OSError(f"{file}: line {number}: expected `world N: r,c r,c …`") from None
    return paths

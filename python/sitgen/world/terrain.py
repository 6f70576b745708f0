"""Terrain generation from Python: :func:`generate_terrain` returns a :class:`Grid`."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.world.config import SpecLike, spec_source


@dataclass(frozen=True)
class Stage:
    """One step of the terrain chain: the source or a filter, and what it left."""

    stage: str
    """``source`` or the filter's kind."""
    coverage: float | None
    """Occupied fraction after this stage, if it produced an occupancy grid."""
    threshold: float | None
    """The level a ``coverage`` filter chose (a signed distance in metres on a grid)."""
    evaluations: int | None = None
    """How many thresholds a ``coverage`` filter tried (each runs the rest of the chain)."""


@dataclass(frozen=True)
class Grid:
    """An occupancy map. Row 0 is the top (north) edge; column 0 the left (west) edge.

    World frame: x east, y north, metres, origin at the bottom-left corner of the map.
    """

    occupied: npt.NDArray[np.bool_]
    """Occupancy, shape (rows, cols), ``True`` = obstacle."""
    resolution: float
    """Cell edge length, metres per cell."""
    seed: int = 0
    """The master seed it was generated with."""
    attempts: int = 1
    """How many times the source was drawn (more than 1 when a coverage constraint could not
    be met by an earlier draw)."""
    stages: tuple[Stage, ...] = ()
    """What each step of the chain did."""
    spec: dict[str, Any] = field(default_factory=dict)
    """The resolved spec (preset applied, defaults filled)."""
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """For a loaded ROS map, the pose (x m, y m, yaw rad) of its bottom-left corner in the ROS
    map frame; sitgen's own frame starts at that corner."""

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) in metres."""
        rows, cols = self.occupied.shape
        return cols * self.resolution, rows * self.resolution

    @property
    def coverage(self) -> float:
        """Occupied fraction of the map, in [0, 1]."""
        return float(self.occupied.mean()) if self.occupied.size else 0.0

    def save(self, image_path: str | Path, *, yaml: bool = True) -> Path | None:
        """Write the map as PNG or PGM (by extension) and, unless ``yaml=False``, a ROS
        map_server YAML with the same stem. Returns the YAML path, if written."""
        image_path = Path(image_path)
        yaml_path = image_path.with_suffix(".yaml") if yaml else None
        _core.write_map(np.ascontiguousarray(self.occupied), self.resolution, image_path, yaml_path)
        return yaml_path


def generate_terrain(spec: SpecLike, seed: int = 0) -> Grid:
    """Generate the terrain of ``spec`` with master seed ``seed``.

    ``spec`` is a path to a TOML file, TOML text, or a dict such as
    ``{"terrain": {"preset": "caves"}}``. The same spec and seed give the same map, byte for
    byte. Raises :exc:`sitgen.SpecError` for a bad spec (the message names the field) and
    :exc:`sitgen.GenerationFailed` when a valid spec produced no map.
    """
    if seed < 0 or seed >= 2**64:
        raise _core.SpecError(f"seed: {seed} is not in [0, 2^64)")
    kind, text = spec_source(spec)
    out = _core.generate_terrain(kind, text, seed)
    stages = tuple(Stage(**s) for s in json.loads(out["stages"]))
    return Grid(
        occupied=out["occupied"],
        resolution=float(out["resolution_m"]),
        seed=seed,
        attempts=int(out["attempts"]),
        stages=stages,
        spec=json.loads(out["spec"]),
    )


def wall_segments(occupied: npt.NDArray[np.bool_], resolution: float) -> npt.NDArray[np.float64]:
    """The walls of an occupancy map as line segments, shape (n, 4): ``x1, y1, x2, y2`` in the
    world frame (metres), one per maximal straight run of cell edges between an occupied and a
    free cell. Outside the map counts as occupied, so the map's border is a wall where a free
    cell meets it. The exact perception hands these to a controller that avoids lines (rather
    than one disc per laser return), as a map-based simulator would."""
    rows, _ = occupied.shape
    occ = occupied.astype(bool)

    def runs(edges: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.intp], ...]:
        # Each row of `edges` as runs of True: (row, first, one past last).
        padded = np.pad(edges.astype(np.int8), ((0, 0), (1, 1)))
        step = np.diff(padded, axis=1)
        starts, ends = np.argwhere(step == 1), np.argwhere(step == -1)
        return starts[:, 0], starts[:, 1], ends[:, 1]

    # Horizontal edges: boundary b lies between rows b-1 and b (b = 0 the top border).
    tall = np.pad(occ, ((1, 1), (0, 0)), constant_values=True)
    b, c0, c1 = runs(tall[:-1, :] != tall[1:, :])
    y = (rows - b) * resolution
    horizontal = np.column_stack([c0 * resolution, y, c1 * resolution, y])
    # Vertical edges: boundary b lies between columns b-1 and b, along the rows.
    wide = np.pad(occ, ((0, 0), (1, 1)), constant_values=True)
    b, r0, r1 = runs((wide[:, :-1] != wide[:, 1:]).T)
    x = b * resolution
    vertical = np.column_stack([x, (rows - r1) * resolution, x, (rows - r0) * resolution])
    return np.vstack([horizontal, vertical]).astype(np.float64)

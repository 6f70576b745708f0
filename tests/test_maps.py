"""Map import and A* through the Python API, checked against the shared reference data."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

import sitgen


def test_movingai_optimal_lengths_on_a_sample_of_every_file(shared_data: Path) -> None:
    scenarios = sorted((shared_data / "movingai" / "scenarios").glob("*/*.scen"))
    assert len(scenarios) == 6
    for scen in scenarios:
        grid = sitgen.load_map(
            shared_data / "movingai" / "maps" / scen.parent.name / scen.name.removesuffix(".scen")
        )
        problems = scen.read_text().splitlines()[1:]
        for line in problems[:: max(1, len(problems) // 25)]:
            f = line.split("\t")
            found = sitgen.shortest_path(grid, (int(f[4]), int(f[5])), (int(f[6]), int(f[7])))
            assert found is not None
            cells, length = found
            assert abs(length - float(f[8])) <= 5e-6 * max(1.0, float(f[8])) + 1e-6
            assert cells[0] == (int(f[4]), int(f[5])) and cells[-1] == (int(f[6]), int(f[7]))


def test_shortest_path_returns_none_without_a_path() -> None:
    blocked = np.array([[False, True], [True, False]])
    assert sitgen.shortest_path(blocked, (0, 0), (1, 1)) is None
    assert sitgen.shortest_path(~blocked, (1, 0), (0, 1)) is None


def test_ros_maps_load_with_their_resolution_and_unknown_policy(shared_data: Path) -> None:
    yaml = shared_data / "rosmaps" / "turtlebot3_noetic" / "map.yaml"
    occupied = sitgen.load_map(yaml)
    free = sitgen.load_map(yaml, unknown_free=True)
    assert occupied.resolution == 0.05
    assert occupied.origin == (-10.0, -10.0, 0.0)
    assert occupied.occupied.shape == (384, 384)
    assert occupied.occupied.sum() > free.occupied.sum()


def test_barn_grids_load_turned_east_north(shared_data: Path) -> None:
    path = shared_data / "barn" / "barn_grids_300x30x30.npy"
    raw = np.load(path)[7]
    grid = sitgen.load_map(path, index=7)
    assert grid.resolution == 0.15
    # BARN rows 0 and 29 are the side walls (x); turned, they are the west and east columns.
    assert raw[0].all() and raw[29].all()
    assert grid.occupied[:, 0].all() and grid.occupied[:, -1].all()
    assert grid.occupied.sum() == raw.sum()
    with pytest.raises(OSError, match="give index"):
        sitgen.load_map(path)


def _barn_paths(shared_data: Path) -> dict[int, list[tuple[int, int]]]:
    paths = {}
    for line in (shared_data / "barn" / "barn_paths.txt").read_text().splitlines():
        if line.startswith("world "):
            head, _, cells = line.partition(":")
            pairs = [tuple(int(v) for v in p.split(",")) for p in cells.split()]
            paths[int(head.split()[1])] = [(r, c) for r, c in pairs]
    return paths


def test_barn_official_paths_are_free_and_a_star_is_no_longer(shared_data: Path) -> None:
    """Every official BARN path lies in the C-space (grid dilated by 5 x 5 cells) of the loaded,
    turned grid; A* joins its ends there, and where the official path cuts no corner (so it
    obeys A*'s rules) A* is at most as long (A* is optimal; the official planner limits turns
    and penalises clearance)."""
    path = shared_data / "barn" / "barn_grids_300x30x30.npy"
    paths = _barn_paths(shared_data)
    assert len(paths) == 300
    checked = 0
    for world, cells in paths.items():
        grid = sitgen.load_map(path, index=world)
        occupied = grid.occupied
        cspace = np.zeros_like(occupied)
        padded = np.pad(occupied, 2, constant_values=False)
        for dr in range(5):
            for dc in range(5):
                cspace |= padded[dr : dr + 30, dc : dc + 30]
        # BARN cell (r, c) is row 29 - c, column r of the turned grid.
        turned = [(r, 29 - c) for r, c in cells]  # (column, row)
        assert not any(cspace[row, col] for col, row in turned), f"world {world}"
        official = sum(
            float(np.hypot(a[0] - b[0], a[1] - b[1])) for a, b in itertools.pairwise(cells)
        )
        found = sitgen.shortest_path(cspace, turned[0], turned[-1])
        assert found is not None, f"world {world}"
        # Where the official path cuts no corner it is a path under A*'s rules too.
        cuts_corner = any(
            a[0] != b[0] and a[1] != b[1] and (cspace[a[1], b[0]] or cspace[b[1], a[0]])
            for a, b in itertools.pairwise(turned)
        )
        if not cuts_corner:
            assert found[1] <= official + 1e-9, f"world {world}: {found[1]} > {official}"
            checked += 1
    assert checked >= 100, f"only {checked} official paths cut no corner"


def test_bad_map_files_name_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "broken.map"
    bad.write_text("type octile\nheight 2\nwidth 3\nmap\n...\n")
    with pytest.raises(OSError, match=r"broken\.map: the map has 1 rows, expected 2"):
        sitgen.load_map(bad)
    with pytest.raises(OSError, match="unknown map format"):
        sitgen.load_map(tmp_path / "x.bmp")

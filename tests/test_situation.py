"""Situations through the Python API: generation invariants, files, export, figures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

import sitgen
from sitgen.world.config import preset_spec


def _footprint_points(robot: sitgen.Robot, n: int = 12) -> np.ndarray:
    b = robot.body
    u = np.linspace(-0.5, 0.5, n)
    bx, by = np.meshgrid(b["origin_x_m"] + b["length_m"] * u, b["width_m"] * u)
    c, s = np.cos(robot.start.heading_rad), np.sin(robot.start.heading_rad)
    x = robot.start.x_m + c * bx - s * by
    y = robot.start.y_m + s * bx + c * by
    return np.stack([x.ravel(), y.ravel()], axis=1)


def _cells(grid: sitgen.Grid, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows = grid.occupied.shape[0]
    cols = np.floor(xy[:, 0] / grid.resolution).astype(int)
    rws = (rows - np.floor(xy[:, 1] / grid.resolution) - 1).astype(int)
    return rws, cols


@settings(max_examples=40, deadline=None)
@given(name=st.sampled_from(sitgen.preset_names()), seed=st.integers(0, 2**64 - 1))
def test_generated_situations_keep_their_invariants(name: str, seed: int) -> None:
    s = sitgen.generate_situation(preset_spec(name), seed=seed)
    grid = s.grid
    mission = s.spec["mission"]
    assert s.robots[0].role == "agent" and all(r.role == "peer" for r in s.robots[1:])
    assert mission["peers_min"] <= len(s.robots) - 1 <= mission["peers_max"]
    for robot in s.robots:
        rows, cols = _cells(grid, _footprint_points(robot))
        assert not grid.occupied[rows, cols].any(), f"robot {robot.id} starts on an obstacle"
        assert robot.waypoints, "every robot has a route"
    # Every agent leg is plannable on the dilated map, and the planned length meets the minimum.
    blocked = _dilated(grid, mission["plan_margin_m"])
    at = (s.agent.start.x_m, s.agent.start.y_m)
    planned = 0.0
    for waypoint in s.agent.waypoints:
        found = sitgen.shortest_path(blocked, _cell(grid, at), _cell(grid, waypoint))
        assert found is not None, "agent leg not plannable"
        planned += found[1] * grid.resolution
        at = waypoint
    assert planned >= mission["min_route_length_m"] - 1e-9
    # Every peer leg is a straight line clear of the dilated map.
    for peer in s.robots[1:]:
        at = (peer.start.x_m, peer.start.y_m)
        for waypoint in peer.waypoints:
            t = np.linspace(0.0, 1.0, 400)[:, None]
            line = np.asarray(at) + t * (np.asarray(waypoint) - np.asarray(at))
            rows, cols = _cells(grid, line)
            assert not blocked[rows, cols].any(), f"peer {peer.id} leg crosses an obstacle"
            at = waypoint


def _cell(grid: sitgen.Grid, xy: tuple[float, float]) -> tuple[int, int]:
    rows, cols = _cells(grid, np.asarray([xy]))
    return int(cols[0]), int(rows[0])


def _dilated(grid: sitgen.Grid, margin_m: float) -> np.ndarray:
    """Cells within margin_m (centre to centre) of an obstacle, by brute-force shifting."""
    reach = int(np.floor(margin_m / grid.resolution))
    occupied = grid.occupied
    out = occupied.copy()
    rows, cols = occupied.shape
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            if (dr * dr + dc * dc) * grid.resolution**2 > margin_m**2 + 1e-12:
                continue
            shifted = np.zeros_like(occupied)
            shifted[max(dr, 0) : rows + min(dr, 0), max(dc, 0) : cols + min(dc, 0)] = occupied[
                max(-dr, 0) : rows + min(-dr, 0), max(-dc, 0) : cols + min(-dc, 0)
            ]
            out |= shifted
    return out


def test_the_same_seed_gives_the_same_file_and_hash(tmp_path: Path) -> None:
    a = sitgen.generate_situation(preset_spec("urban"), seed=8)
    b = sitgen.generate_situation(preset_spec("urban"), seed=8)
    assert a.to_json() == b.to_json()
    assert a.content_hash_matches()
    a.save(tmp_path / "s.json")
    loaded = sitgen.Situation.load(tmp_path / "s.json")
    assert loaded.to_json() == a.to_json()
    assert np.array_equal(loaded.grid.occupied, a.grid.occupied)
    assert loaded.robots == a.robots


def test_an_edited_situation_loads_but_its_hash_no_longer_matches(tmp_path: Path) -> None:
    s = sitgen.generate_situation(preset_spec("maze"), seed=2)
    data = json.loads(s.to_json())
    data["robots"][0]["start"]["x_m"] += 0.5
    edited = sitgen.Situation(json.dumps(data))
    assert not edited.content_hash_matches()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["robots"][0]["start"].update(x_m="far"), "robots[0].start.x_m: invalid type"),
        (lambda d: d["robots"][1].update(role="agent"), "robots[1].role: the first robot"),
        (lambda d: d["map"].update(rows=3), "map.data: holds"),
        (lambda d: d.update(colour=1), "colour: unknown field `colour`"),
        (lambda d: d.update(format="other/9"), "format: `other/9` is not supported"),
    ],
)
def test_bad_situation_files_name_the_field(tmp_path: Path, edit: object, message: str) -> None:
    s = sitgen.generate_situation({"mission": {"peers_min": 2}, "terrain": {"preset": "caves"}})
    data = json.loads(s.to_json())
    edit(data)  # type: ignore[operator]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(sitgen.SpecError) as info:
        sitgen.Situation.load(path)
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


def test_a_situation_can_start_from_a_loaded_map(shared_data: Path) -> None:
    spec = {
        "terrain": {
            "resolution_m": 0.1,
            "source": {"kind": "map", "path": str(shared_data / "rosmaps/nav2_bringup/depot.yaml")},
        },
        "mission": {"min_route_length_m": 10.0, "peers_max": 2},
    }
    s = sitgen.generate_situation(spec, seed=1)
    assert s.grid.size_m == pytest.approx((30.2, 15.4))
    assert len(s.agent.waypoints) >= 1


def test_stage_export_writes_a_loadable_world(tmp_path: Path) -> None:
    s = sitgen.generate_situation(preset_spec("indoor"), seed=4)
    files = s.export(tmp_path / "stage", "stage")
    names = sorted(p.name for p in files)
    assert names == [
        "edge.png",
        "run.json",
        "sitgen.inc",
        "situation.json",
        "situation.world",
        "terrain.png",
    ]
    world = (tmp_path / "stage" / "situation.world").read_text()
    assert 'include "sitgen.inc"' in world and 'bitmap "terrain.png"' in world
    bitmap = np.asarray(Image.open(tmp_path / "stage" / "terrain.png"))
    # Stage reads a pixel as an obstacle when it is <= 127: one pixel per map cell.
    assert np.array_equal(bitmap <= 127, s.grid.occupied)
    # The edge is a one-pixel frame around the map, free inside.
    edge = np.asarray(Image.open(tmp_path / "stage" / "edge.png")) <= 127
    assert edge.shape == (s.grid.occupied.shape[0] + 2, s.grid.occupied.shape[1] + 2)
    assert edge[0].all() and edge[-1].all() and edge[:, 0].all() and edge[:, -1].all()
    assert not edge[1:-1, 1:-1].any()
    # The situation travels with the world, for the plugin's controllers.
    assert sitgen.Situation.load(tmp_path / "stage" / "situation.json").content_hash == (
        s.content_hash
    )


def test_stage_export_takes_the_run_spec(tmp_path: Path) -> None:
    import json

    s = sitgen.generate_situation(preset_spec("caves"), seed=4)
    run = {"profile": "paper", "time_limit_s": 120}
    s.export(tmp_path, "stage", run=run)
    resolved = json.loads((tmp_path / "run.json").read_text())
    assert resolved["time_limit_s"] == 120 and resolved["sim"]["laser"]["beams"] == 180
    assert resolved["controller"]["control_period_s"] == 0.5
    world = (tmp_path / "situation.world").read_text()
    assert "quit_time 120.1" in world
    include = (tmp_path / "sitgen.inc").read_text()
    assert "fov 180 samples 180" in include
    assert "velocity_bounds [-0.5 0.5 0 0 0 0 -90 90]" in include
    with pytest.raises(sitgen.SpecError, match=r"run\.time_limit_s"):
        s.export(tmp_path / "bad", "stage", run={"time_limit_s": -1})


def test_ros_export_round_trips_through_load_map(tmp_path: Path) -> None:
    s = sitgen.generate_situation(preset_spec("caves"), seed=6)
    s.export(tmp_path / "ros", "ros")
    grid = sitgen.load_map(tmp_path / "ros" / "map.yaml")
    assert grid.resolution == s.grid.resolution
    assert np.array_equal(grid.occupied, s.grid.occupied)


def test_the_figure_is_drawn_in_the_papers_style(tmp_path: Path) -> None:
    from sitgen.world.figure import AGENT, PEER, ROUTE, save_situation_figure

    s = sitgen.generate_situation(
        {"terrain": {"preset": "open_field"}, "mission": {"peers_min": 2}}
    )
    save_situation_figure(s, tmp_path / "fig.png")
    pixels = np.asarray(Image.open(tmp_path / "fig.png").convert("RGB")).reshape(-1, 3)
    colours = {tuple(int(v) for v in p) for p in np.unique(pixels, axis=0)}
    assert {AGENT, PEER, ROUTE} <= colours


def _stage_m_per_px(bitmap: Path | np.ndarray, size_x: float, size_y: float) -> tuple[float, float]:
    """Stage's scaling: the bounding box of pixels whose first channel is <= 127 is stretched
    to the model's size."""
    if isinstance(bitmap, Path):
        opened = Image.open(bitmap)
        # The first channel: grey for grey and 1-bit images, red otherwise.
        bitmap = np.asarray(opened.convert("L" if opened.mode in ("1", "L", "I") else "RGB"))
    first = bitmap[..., 0] if bitmap.ndim == 3 else bitmap
    dark_rows, dark_cols = np.nonzero(first.astype(int) <= 127)
    width = dark_cols.max() - dark_cols.min() + 1
    height = dark_rows.max() - dark_rows.min() + 1
    return size_x / width, size_y / height


def test_the_stage_scaling_rule_matches_the_shared_worlds_and_our_export(
    shared_data: Path, tmp_path: Path
) -> None:
    table = (shared_data / "stage" / "world_bitmap_table.tsv").read_text().splitlines()
    header = table[0].split("\t")
    checked = 0
    for line in table[1:]:
        row = dict(zip(header, line.split("\t"), strict=True))
        bitmap = shared_data / "stage" / "worlds" / "bitmaps" / row["bitmap"]
        if not bitmap.is_file():
            continue
        size = [float(v) for v in row["size_xyz_m"].split()]
        mx, my = _stage_m_per_px(bitmap, size[0], size[1])
        assert abs(mx - float(row["eff_m_per_px_x"])) < 1e-5, row["world_file"]
        assert abs(my - float(row["eff_m_per_px_y"])) < 1e-5, row["world_file"]
        checked += 1
    assert checked >= 3
    s = sitgen.generate_situation(preset_spec("rocky_desert"), seed=2)
    s.export(tmp_path, "stage")
    world = (tmp_path / "situation.world").read_text()
    terrain = world[world.index("sitgen_terrain\n(") :]
    size_line = next(line for line in terrain.splitlines() if line.strip().startswith("size ["))
    sx, sy, _ = (float(v) for v in size_line.strip()[6:-1].split())
    mx, my = _stage_m_per_px(tmp_path / "terrain.png", sx, sy)
    assert mx == pytest.approx(s.grid.resolution) and my == pytest.approx(s.grid.resolution)

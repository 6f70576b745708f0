"""Terrain generation through the Python API."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sitgen
from sitgen.world.config import preset_spec


def _coverage_target(grid: sitgen.Grid) -> tuple[float, float]:
    for f in grid.spec["terrain"]["filters"]:
        if f["kind"] == "coverage":
            return float(f["target"]), float(f["tolerance"])
    raise AssertionError("every preset has a coverage constraint")


def test_perlin_matches_every_reference_value(shared_data: Path) -> None:
    rows = (shared_data / "perlin" / "perlin_improved_noise_values.tsv").read_text().splitlines()
    header = rows[0].split("\t")
    assert header[:5] == ["x", "y", "z", "noise_ref", "noise_ref_hex"]
    for row in rows[1:]:
        x, y, z, _, hex_value = row.split("\t")[:5]
        expected = float.fromhex(hex_value)
        assert sitgen.perlin(float(x), float(y), float(z)) == expected, (x, y, z)
    assert len(rows) == 536


def test_perlin_anchor_values_and_lattice_zeros() -> None:
    assert sitgen.perlin(3.14, 42.0, 7.0) == 0.13691995878400012
    assert sitgen.perlin(-4.2, 10.0) == -0.14208000000000043
    assert sitgen.perlin(0.5, 0.5, 0.5) == -0.25
    assert all(sitgen.perlin(i, -i, 2 * i) == 0.0 for i in range(-5, 6))


def test_a_spec_can_be_a_path_toml_text_or_a_dict(tmp_path: Path) -> None:
    text = '[terrain]\npreset = "maze"\nwidth_m = 12.0\nheight_m = 9.0\n'
    path = tmp_path / "spec.toml"
    path.write_text(text)
    grids = [
        sitgen.generate_terrain(path, seed=4),
        sitgen.generate_terrain(str(path), seed=4),
        sitgen.generate_terrain(text, seed=4),
        sitgen.generate_terrain(
            {"terrain": {"preset": "maze", "width_m": 12.0, "height_m": 9.0}}, seed=4
        ),
    ]
    for g in grids[1:]:
        assert np.array_equal(g.occupied, grids[0].occupied)
    g = grids[0]
    assert g.occupied.dtype == np.bool_
    assert g.occupied.shape == (90, 120)
    assert g.size_m == pytest.approx((12.0, 9.0))
    assert g.resolution == 0.1


@pytest.mark.parametrize("name", sitgen.preset_names())
def test_every_preset_is_byte_identical_for_a_seed(name: str) -> None:
    a = sitgen.generate_terrain(preset_spec(name), seed=21)
    b = sitgen.generate_terrain(preset_spec(name), seed=21)
    c = sitgen.generate_terrain(preset_spec(name), seed=22)
    assert a.occupied.tobytes() == b.occupied.tobytes()
    assert a.occupied.tobytes() != c.occupied.tobytes()
    assert a.stages == b.stages


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sitgen.preset_names()), seed=st.integers(0, 2**64 - 1))
def test_presets_meet_their_coverage_for_any_seed(name: str, seed: int) -> None:
    grid = sitgen.generate_terrain(preset_spec(name), seed=seed)
    target, tolerance = _coverage_target(grid)
    assert abs(grid.coverage - target) <= tolerance
    assert grid.stages[-1].coverage == pytest.approx(grid.coverage)


@settings(max_examples=25, deadline=None)
@given(
    target=st.floats(0.05, 0.6),
    block_m=st.sampled_from([0.1, 0.3, 0.5]),
    seed=st.integers(0, 10_000),
)
def test_the_paper_chain_hits_any_target(target: float, block_m: float, seed: int) -> None:
    spec = {
        "terrain": {
            "width_m": 20.0,
            "height_m": 15.0,
            "filters": [
                {"kind": "pixelise", "block_m": block_m},
                {"kind": "coverage", "target": target, "tolerance": 0.01},
            ],
        }
    }
    grid = sitgen.generate_terrain(spec, seed=seed)
    assert abs(grid.coverage - target) <= 0.01


def test_row_zero_is_the_top_of_an_image(tmp_path: Path) -> None:
    from PIL import Image

    picture = np.full((20, 30), 255, dtype=np.uint8)
    picture[0:5, :] = 0  # black band along the top
    Image.fromarray(picture).save(tmp_path / "band.png")
    spec = {
        "terrain": {
            "source": {"kind": "image", "path": str(tmp_path / "band.png")},
            "filters": [{"kind": "threshold", "value": 0.5}],
        }
    }
    grid = sitgen.generate_terrain(spec)
    assert grid.occupied.shape == (20, 30)
    assert grid.occupied[:5].all() and not grid.occupied[5:].any()
    assert grid.size_m == pytest.approx((3.0, 2.0))


def test_a_saved_map_reads_back_with_its_ros_yaml(tmp_path: Path) -> None:
    import yaml
    from PIL import Image

    grid = sitgen.generate_terrain(preset_spec("caves"), seed=5)
    yaml_path = grid.save(tmp_path / "caves.png")
    assert yaml_path == tmp_path / "caves.yaml"
    meta = yaml.safe_load(yaml_path.read_text())
    assert meta["image"] == "caves.png"
    assert meta["resolution"] == 0.1 and meta["negate"] == 0
    assert meta["origin"] == [0.0, 0.0, 0.0]
    pixels = np.asarray(Image.open(tmp_path / "caves.png"))
    # ROS: occupancy probability (255 - value) / 255 above occupied_thresh means occupied.
    occupied = (255 - pixels.astype(float)) / 255 > meta["occupied_thresh"]
    assert np.array_equal(occupied, grid.occupied)


def test_seeds_outside_64_bits_are_rejected() -> None:
    with pytest.raises(sitgen.SpecError, match="seed"):
        sitgen.generate_terrain(preset_spec("maze"), seed=-1)


def test_generation_failure_names_the_stage() -> None:
    spec = {
        "terrain": {
            "width_m": 10.0,
            "height_m": 10.0,
            "filters": [
                {"kind": "coverage", "target": 0.05, "tolerance": 0.001},
                {"kind": "border", "width_m": 2.0},
            ],
        }
    }
    with pytest.raises(sitgen.GenerationFailed, match=r"^terrain\.filters\[0\]: after 8 draws"):
        sitgen.generate_terrain(spec, seed=1)


def test_keep_largest_free_region_leaves_one_region() -> None:
    # Tiny rooms with walls everywhere would leave sealed pockets without the filter.
    grid = sitgen.generate_terrain(preset_spec("caves"), seed=77)
    free = ~grid.occupied
    seen = np.zeros_like(free)
    regions = 0
    for start in zip(*np.nonzero(free), strict=True):
        if seen[start]:
            continue
        regions += 1
        stack = [start]
        seen[start] = True
        while stack:
            r, c = stack.pop()
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    nr, nc = r + dr, c + dc
                    inside = 0 <= nr < free.shape[0] and 0 <= nc < free.shape[1]
                    if inside and free[nr, nc] and not seen[nr, nc]:
                        seen[nr, nc] = True
                        stack.append((nr, nc))
    assert regions == 1

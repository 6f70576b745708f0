"""The simulator through the Python API."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import sitgen
from sitgen.world.config import preset_spec


def _situation() -> sitgen.Situation:
    return sitgen.generate_situation(
        {"terrain": {"preset": "caves"}, "mission": {"peers_min": 2, "peers_max": 2}}, seed=5
    )


def test_observe_step_and_state_from_python() -> None:
    world = sitgen.World(_situation())
    o = world.observe(0)
    assert o.ranges.dtype == np.float64 and o.ranges.shape == (181,)
    assert o.angles[0] == pytest.approx(-math.pi / 2) and o.angles[-1] == pytest.approx(math.pi / 2)
    assert ((o.ranges >= 0) & (o.ranges <= 10.0)).all()
    x0, y0, _ = o.pose
    world.step({0: (0.3, 0.0)})
    world.step()
    o = world.observe(0)
    assert o.time == pytest.approx(0.2) and world.steps == 2
    # Robots start with clearance_m (0.1 m) to spare, so 6 cm straight ahead is always free.
    assert not o.stalled
    assert math.hypot(o.pose[0] - x0, o.pose[1] - y0) == pytest.approx(0.06)
    state = world.state()
    assert [r["role"] for r in state] == ["agent", "peer", "peer"]
    assert state[0]["command"] == (0.3, 0.0)
    assert world.observe(1).ranges.size == 0
    for track in world.observe(0).tracks:
        assert track["id"] in (1, 2) and len(track["position"]) == 2


def test_the_same_inputs_give_the_same_trajectory() -> None:
    def run() -> list[tuple[float, ...]]:
        world = sitgen.World(_situation(), {"laser": {"noise_sd_m": 0.01}}, seed=3)
        poses: list[tuple[float, ...]] = []
        for k in range(100):
            world.step({r.id: (0.5, 0.2 * ((k + r.id) % 3 - 1)) for r in world.situation.robots})
            poses.extend(tuple(r["pose"]) for r in world.state())
            poses.append(tuple(world.observe(0).ranges[:3]))
        return poses

    assert run() == run()


def test_bad_settings_and_commands_are_clear_errors() -> None:
    with pytest.raises(sitgen.SpecError, match=r"^sim\.laser\.beams: 0 is not in \[1, 10000\]"):
        sitgen.World(_situation(), {"laser": {"beams": 0}})
    with pytest.raises(sitgen.SpecError, match="unknown field `dt`"):
        sitgen.World(_situation(), {"dt": 0.1})
    world = sitgen.World(_situation())
    with pytest.raises(ValueError, match="no robot 9"):
        world.step({9: (0.1, 0.0)})


def test_a_situation_file_can_be_given(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    sitgen.generate_situation(preset_spec("maze"), seed=1).save(path)
    world = sitgen.World(path)
    world.advance(50)
    assert world.steps == 50

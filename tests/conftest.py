"""Shared fixtures: the reference data beside the repository, a CLI runner and a real
headless Chromium (Debian's, driven by Playwright; nothing downloads a browser)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sitgen
from sitgen import _core
from sitgen.world.situation import Situation

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (or ``$SITGEN_SHARED_DATA``); skips the test when it is absent."""
    path = Path(os.environ.get("SITGEN_SHARED_DATA", ROOT.parent / "shared" / "data"))
    if not path.is_dir():
        pytest.skip(f"reference data not found at {path} (set SITGEN_SHARED_DATA)")
    return path


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


def sitgen_command() -> list[str]:
    exe = shutil.which("sitgen", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "sitgen.cli"]


def campaign_on_2_and_1_workers(text: str, folder: Path) -> tuple[Path, Path]:
    """The campaign spec ``text`` run with ``sitgen campaign`` on 2 workers, then on 1 (no
    robustness copies): the two stores, ``2.db`` and ``1.db`` in ``folder``."""
    spec = folder / "campaign.toml"
    spec.write_text(text)
    stores = (folder / "2.db", folder / "1.db")
    for db, workers in zip(stores, ("2", "1"), strict=True):
        done = run_cli(
            "campaign", str(spec), "--db", str(db), "--workers", workers, "--reruns", "0",
            cwd=ROOT,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
    return stores


def run_cli(*args: str, cwd: Path | None = None) -> Result:
    """Run the installed ``sitgen`` command, as a user would."""
    done = subprocess.run(
        [*sitgen_command(), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
        check=False,
    )
    return Result(done.returncode, done.stdout, done.stderr)


@pytest.fixture(scope="module")
def situation() -> sitgen.Situation:
    """An open field with two peers and a 15 m route, for runs of any controller."""
    spec = {
        "terrain": {"preset": "open_field"},
        "mission": {"peers_min": 2, "peers_max": 2, "min_route_length_m": 15.0},
    }
    return sitgen.generate_situation(spec, seed=1)


@pytest.fixture(scope="module")
def situation_file(situation: sitgen.Situation, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """That situation, saved as a file."""
    path = tmp_path_factory.mktemp("situation") / "situation.json"
    situation.save(path)
    return path


CHROMIUM = os.environ.get("SITGEN_CHROMIUM", "/usr/bin/chromium")


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium, or set SITGEN_CHROMIUM)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        yield b
        b.close()


def open_page(browser: Any, path: Path) -> tuple[Any, list[str]]:
    """A page of ``path`` and the console errors it logs."""
    page = browser.new_page(viewport={"width": 1280, "height": 1000})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(path.as_uri())
    return page, errors


LONGEST_FIRST = (
    "test_ros2.py",
    "test_reliability.py",
    "test_ros2_styles.py",
    "test_guide.py",
    "test_diff.py",
    "test_mutation.py",
    "test_weights.py",
    "test_campaign.py",
    "test_search.py",
)
"""The test files that take longest, longest first (seconds of their tests on an idle 2-core
machine, 374 down to 102): `make py-test` hands a worker a file at a time in collection order,
and a long file taken last keeps one worker busy after the other has finished."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest files first (:data:`LONGEST_FIRST`), then the rest as collected."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def two_robots(agent: tuple[float, float, float], peer: tuple[float, float, float],
               peer_goal: list[float], peer_controller: dict[str, Any]) -> Situation:  # fmt: skip
    """A 20 m square with nothing in it: the agent (route 12 m east) and one peer."""
    base = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=1)
    template = json.loads(base.to_json())["robots"][0]
    robots = [
        {
            **template,
            "id": i,
            "role": role,
            "at_end": "stop",
            "start": {"x_m": x, "y_m": y, "heading_rad": h},
            "waypoints": [goal],
            "controller": controller,
        }
        for i, (role, (x, y, h), goal, controller) in enumerate(
            [
                ("agent", agent, [agent[0] + 12.0, agent[1]], {"name": "snd_follow"}),
                ("peer", peer, peer_goal, peer_controller),
            ]
        )
    ]
    empty = np.zeros((200, 200), dtype=bool)
    return Situation(_core.shrunk_situation(base.to_json(), empty, 0.1, json.dumps(robots)))


@contextlib.contextmanager
def spinning(count: int, sessions: bool = True) -> Iterator[None]:
    """``count`` processes that only spin, for the block: a loaded machine. ``sessions``: each
    in a session of its own, as other jobs of a loaded machine are (the scheduler shares a
    core out by session, so a process of sitgen's then gets 1/(count per core + 1) of one)."""
    loops = [
        subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=sessions)
        for _ in range(count)
    ]
    try:
        yield
    finally:
        for loop in loops:
            loop.kill()
            loop.wait()


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie waiting to be reaped does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False

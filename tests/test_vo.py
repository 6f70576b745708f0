"""Velocity Obstacles meeting Velocity Obstacles: the example campaign (a vo agent among vo
peers, each with a laser) shows the oscillations the paper expected to find, and both parties
of an encounter oscillate about each other."""

from __future__ import annotations

import json
from pathlib import Path

from sitgen.store import Store
from tests.conftest import ROOT, run_cli


def test_the_vo_example_produces_oscillation_events_of_the_agent_and_its_peers(
    tmp_path: Path,
) -> None:
    db = tmp_path / "vo.db"
    spec = ROOT / "examples" / "campaigns" / "vo.toml"
    done = run_cli("campaign", str(spec), "-n", "40", "--seed", "1", "--db", str(db))
    assert done.returncode == 0, done.stderr
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT run_id, robot, start_s, end_s, details FROM events WHERE kind = 'oscillation'"
        ).fetchall()
        run_spec = json.loads(store.db.execute("SELECT run_spec FROM runs").fetchone()[0])
    assert run_spec["controller"]["name"] == "vo"
    events = [
        (run, robot, start, end or start, json.loads(details)["nearest"])
        for run, robot, start, end, details in rows
    ]
    assert any(robot == 0 for _, robot, *_ in events), "the agent never oscillated"
    # Peers carry lasers and avoid too, so they oscillate as well; in some run a peer and the
    # agent oscillate at the same time, each nearest the other.
    mutual = [
        (a[0], a[2], b[2])
        for a in events
        for b in events
        if a[0] == b[0]
        and a[1] == 0
        and a[4] == b[1]
        and b[4] == 0
        and a[2] <= b[3]
        and b[2] <= a[3]
    ]
    assert mutual, events

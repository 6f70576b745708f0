"""The fast path for Python controllers: a class called in the pool worker's process, from the
core's step loop, gives the same runs, byte for byte, as the same class in a host process of
its own over the JSON-lines protocol; and a failure in it ends only its run, with the host's
reason (tests/test_reliability.py drives the failures through the CLI)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

import sitgen
from sitgen.execution.jobs import build_jobs, campaign_from_data
from sitgen.execution.workers import run_user_job
from tests.conftest import ROOT

CAUTIOUS = f"python:{ROOT / 'examples' / 'controllers' / 'cautious.py'}:Cautious"
WATCHFUL = "python:tests.controllers.pycontrollers:Watchful"


def campaign(controller: str, n: int) -> dict[str, Any]:
    """A short campaign of mixed terrain and 0-3 peers (every input a controller reads varies:
    scans near and far, tracks, waypoints, stalls)."""
    return {
        "n": n,
        "situation": {"terrain": {"preset": "open_field"}, "mission": {"peers_max": 3}},
        "run": {"time_limit_s": 10.0, "controller": {"name": controller}},
        "vary": {"situation.terrain.preset": {"choice": ["open_field", "caves", "indoor"]}},
    }


def test_a_100_run_campaign_is_the_same_on_the_fast_path_and_in_a_host_process() -> None:
    jobs = build_jobs(campaign_from_data(campaign(CAUTIOUS, 60)), 5, 60)
    jobs += build_jobs(campaign_from_data(campaign(WATCHFUL, 40)), 6, 40)
    classes = set()
    for job in jobs:
        host = run_user_job(job, in_process=False)
        fast = run_user_job(job, in_process=True)
        assert host["ok"] and fast["ok"], (host, fast)
        # What a run cost is the machine's (a host process costs more), not the run's.
        cost = ("wall_s", "cpu_s")
        assert {k: v for k, v in fast.items() if k not in cost} == {
            k: v for k, v in host.items() if k not in cost
        }, f"job {job.index} of {job.controller} differs"
        record = json.loads(fast["record"])
        classes.add(record["failure"] and record["failure"]["class"])
    assert len(classes) >= 2, f"the runs are not all alike: {classes}"


def test_an_object_handed_to_run_sees_what_a_host_process_gives_it() -> None:
    from tests.controllers.pycontrollers import Watchful

    situation = sitgen.generate_situation(
        {"terrain": {"preset": "indoor"}, "mission": {"peers_min": 2, "peers_max": 2}}, seed=3
    )
    watched = Watchful()
    obj = sitgen.run(situation, controller=watched, time_limit=20.0, seed=1)
    host = sitgen.run(situation, controller=WATCHFUL, time_limit=20.0, seed=1)
    assert obj.events_jsonl == host.events_jsonl
    assert np.array_equal(obj.trajectory, host.trajectory)
    # Each step's scan is an array of its own, so a controller may write into it.
    assert watched.scans > 10 and watched.shared_scans == 0

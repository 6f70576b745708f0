"""The fast path as safe as the host process: a ``python:`` class called in a campaign's pool
worker (or a ``python:`` peer stepped in sitgen's own process) that does what ordinary or
careless Python code does — raises from a ``__float__``, starts threads and children, forks,
kills its process group, leaves signal handlers — ends, hangs or kills nothing but its own run,
gets the reason the host process gives, and leaves no process behind (checked from /proc)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT, Result, alive, sitgen_command, two_robots

CARELESS = "python:tests.controllers.careless"
PY = "python:tests.controllers.pycontrollers"

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

BOTH_PATHS = """
import json, sys
import sitgen
from tests.conftest import two_robots
situation = sitgen.generate_situation({"terrain": {"preset": "open_field"},
    "mission": {"peers_min": 2, "peers_max": 2, "min_route_length_m": 15.0}}, seed=1)
out = {}
for fast in (False, True):
    r = sitgen.run(situation, controller=sys.argv[1], time_limit=3.0, in_process=fast)
    out["fast" if fast else "host"] = [r.outcome, r.reason]
print(json.dumps(out))
"""


@pytest.mark.parametrize(
    "controller",
    [
        f"{CARELESS}:ExitsInFloat",
        f"{CARELESS}:InterruptsInFloat",
        f"{CARELESS}:RaisesUnprintable",
        f"{CARELESS}:ReturnsDigits",
        f"{CARELESS}:ReturnsBytes",
        f"{CARELESS}:SwallowsTheTimeout",
        f"{CARELESS}:KillsItsGroup",
        f"{CARELESS}:ForksWithoutExec",
        f"{CARELESS}:ExitsInClose",
        f"{CARELESS}:StartsAThread",
        f"{PY}:Raises",
        f"{PY}:Exits",
        f"{PY}:HardExits",
        f"{PY}:Segfaults",
        f"{PY}:HoldsTheGil",
    ],
)
def test_the_fast_path_and_the_host_give_a_misbehaving_class_the_same_reason(
    controller: str,
) -> None:
    """Field by field where it matters: the outcome and the one-line reason, from a process
    of its own (so that what escapes would end it, not the tests)."""
    done = subprocess.run(
        [sys.executable, "-c", BOTH_PATHS, controller],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    both = json.loads(done.stdout.strip().splitlines()[-1])
    # A reason's hint, computing or waiting, is measured from the processor time the class
    # gets over a short look, which a loaded machine changes: the reason itself is compared.
    fast, host = ([o, r.split("; it is ")[0]] for o, r in (both["fast"], both["host"]))
    assert fast == host, both
    if "Returns" in controller:
        assert "expected (v, omega) numbers" in both["fast"][1], both
    if "SwallowsTheTimeout" in controller or "HoldsTheGil" in controller:
        assert "did not reply within 1 s of processor time at 0.3 s" in both["fast"][1], both


def _campaign(tmp_path: Path, controller: str, n: int = 4, time_limit_s: float = 5.0) -> Path:
    spec = tmp_path / "careless.toml"
    spec.write_text(
        f'n = {n}\n[situation.terrain]\npreset = "open_field"\n'
        f"[situation.mission]\npeers_min = 0\npeers_max = 1\n"
        f"[run]\ntime_limit_s = {time_limit_s}\n[run.controller]\nname = {json.dumps(controller)}\n"
    )
    return spec


def _sitgen(tmp_path: Path, *args: str, timeout_s: float = 90.0) -> tuple[Result, list[int]]:
    """The command as CI runs it, its output read through pipes to their end (a daemon that
    kept them open would hold this call), and the processes its controllers recorded."""
    pids = tmp_path / "pids"
    env = {**os.environ, "SITGEN_TEST_PIDS": str(pids)}
    proc = subprocess.Popen(
        [*sitgen_command(), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        # Whatever still holds the pipes (sitgen or what a class left) is in its session.
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    recorded = [int(p) for p in pids.read_text().split()] if pids.exists() else []
    return Result(proc.returncode, out, err), recorded


def _stored(db: Path) -> list[tuple[str, str]]:
    with sqlite3.connect(db) as c:
        return c.execute("SELECT outcome, reason FROM runs ORDER BY id").fetchall()


@pytest.mark.parametrize("careless", ["StartsAChild", "DoubleForks"])
def test_what_a_class_starts_ends_with_its_run_in_every_command(
    tmp_path: Path, careless: str
) -> None:
    """A program started at reset, and a daemon forked twice that keeps the worker's files
    open: neither outlives its run, so the campaign's output reaches its end when it exits."""
    db = tmp_path / "c.db"
    done, pids = _sitgen(tmp_path, "campaign", str(_campaign(tmp_path, f"{CARELESS}:{careless}")),
                         "--db", str(db), "--workers", "2")  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    # Each run and each of its robustness copies started one.
    assert len(pids) >= 4 and len(_stored(db)) == 4, (pids, _stored(db))
    assert [p for p in pids if alive(p)] == [], "nothing a run started outlives it"
    again, more = _sitgen(tmp_path, "robustness", str(db), "0", "--reruns", "2")
    assert again.returncode in (0, 1), again.stdout + again.stderr
    assert len(more) == len(pids) + 2 and [p for p in more if alive(p)] == []


def test_a_campaign_killed_outright_leaves_nothing_its_classes_started(tmp_path: Path) -> None:
    db = tmp_path / "killed.db"
    pids = tmp_path / "pids"
    spec = _campaign(tmp_path, f"{CARELESS}:DoubleForksSlowly", n=40, time_limit_s=60.0)
    proc = subprocess.Popen(
        [*sitgen_command(), "campaign", str(spec), "--db", str(db), "--workers", "2"],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "SITGEN_TEST_PIDS": str(pids)},
    )
    try:
        deadline = time.monotonic() + 60
        while (not pids.exists() or len(pids.read_text().split()) < 2) and (
            time.monotonic() < deadline
        ):
            time.sleep(0.05)
        started = [int(p) for p in pids.read_text().split()]
        assert any(alive(p) for p in started), "a daemon at work"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 20
    while any(alive(p) for p in started) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert [p for p in started if alive(p)] == [], "no daemon outlives a killed campaign"


@pytest.mark.parametrize(
    ("careless", "outcome", "reason"),
    [
        ("StartsAThread", "timeout", "route not completed"),
        ("SlowClose", "timeout", "route not completed"),
        ("SendsAlarms", "timeout", "route not completed"),
        ("KillsItsGroup", "error", "was killed by SIGTERM at 0.3 s"),
        ("ForksWithoutExec", "timeout", "route not completed"),
    ],
)
def test_a_class_cannot_hang_or_end_the_campaign_or_reach_later_runs(
    tmp_path: Path, careless: str, outcome: str, reason: str
) -> None:
    """A non-daemon thread that never ends, a ``close`` of a minute (the end of a run
    bounds it as a program's exit), a thread that sends SIGALRM to its process, a
    ``killpg(0, SIGTERM)``, a fork whose two halves both return: every run is stored with the
    class's own outcome, and the command ends."""
    db = tmp_path / "c.db"
    done, _ = _sitgen(tmp_path, "campaign", str(_campaign(tmp_path, f"{CARELESS}:{careless}")),
                      "--db", str(db), "--workers", "2", timeout_s=50)  # fmt: skip
    assert done.returncode in (0, 1), done.stdout + done.stderr
    runs = _stored(db)
    assert len(runs) == 4, runs
    assert all(o == outcome and reason in r for o, r in runs), runs


@pytest.mark.parametrize(
    ("careless", "reason"),
    [
        ("pycontrollers:Segfaults", "was killed by SIGSEGV at 0.3 s"),
        ("pycontrollers:HardExits", "exited with code 7 at 0.3 s"),
        ("careless:KillsItsGroup", "was killed by SIGTERM at 0.3 s"),
        ("pycontrollers:HoldsTheGil", "did not reply within 1 s of processor time at 0.3 s"),
    ],
)
def test_a_python_peer_that_kills_its_process_ends_sitgen_run_with_a_reason(
    tmp_path: Path, careless: str, reason: str
) -> None:
    """`sitgen run` steps a run with a ``python:`` peer in a runner: a peer that crashes,
    calls ``os._exit``, kills its group or holds the GIL in C past its timeout is that run's
    error, named, and the command says so with exit code 1 (never 139, a silent 0 or a hang)."""
    name = f"python:tests.controllers.{careless}"
    situation = two_robots((4.0, 10.0, 0.0), (4.0, 14.0, 0.0), [15.0, 14.0], {"name": name})
    path = tmp_path / "peer.json"
    situation.save(path)
    done, _ = _sitgen(tmp_path, "run", str(path), "--time-limit", "5")
    assert done.returncode == 1, done.stdout + done.stderr
    assert f"controller `{name}` of peer 1 {reason}" in done.stdout, done.stdout


def test_a_class_from_a_file_can_pickle_its_own_functions(tmp_path: Path) -> None:
    """A ``python:FILE.py`` module is in ``sys.modules`` as an import would put it, so that
    multiprocessing (pickle) finds what it defines."""
    module = tmp_path / "pickling_controller.py"
    module.write_text(
        "import pickle\n\n"
        "def half(x):\n    return x / 2\n\n"
        "class Pickles:\n"
        "    def reset(self, info):\n        self.half = pickle.loads(pickle.dumps(half))\n"
        "    def act(self, obs):\n        return self.half(0.6), 0.0\n"
    )
    db = tmp_path / "c.db"
    done, _ = _sitgen(tmp_path, "campaign", str(_campaign(tmp_path, f"python:{module}:Pickles")),
                      "--db", str(db), "--workers", "1")  # fmt: skip
    assert done.returncode in (0, 1), done.stdout + done.stderr
    assert all(o != "error" for o, _ in _stored(db)), _stored(db)


IN_TURN = """
import sys
import sitgen
situation = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=1)
for name in sys.argv[1:]:
    sitgen.run(situation, controller=f"python:tests.controllers.careless:{name}",
               time_limit=1.0, in_process=True)
"""


def test_a_run_that_changes_its_process_leaves_the_next_a_fresh_one(tmp_path: Path) -> None:
    """Runs are made one after another by one process while each leaves it as it found it;
    a run that leaves a thread or a signal handler behind is the last that process makes, so
    nothing of it reaches the next run."""
    pids = tmp_path / "pids"
    order = ["RecordsItsProcess", "RecordsItsProcess", "SendsAlarms", "RecordsItsProcess",
             "StartsAThread", "RecordsItsProcess"]  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-c", IN_TURN, *order],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        env={**os.environ, "SITGEN_TEST_PIDS": str(pids)},
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    seen = [line.split() for line in pids.read_text().splitlines()]
    assert len(seen) == 4, seen
    assert seen[0][0] == seen[1][0], "a clean run leaves its process for the next"
    assert seen[2][0] != seen[1][0] and seen[3][0] != seen[2][0], "a dirty one does not"
    assert all(handler == "True" and threads == "1" for _, handler, threads in seen), seen


FORKED_RUN = """
import json, os, sys
import sitgen
from sitgen import _core
situation = sitgen.generate_situation({"terrain": {"preset": "caves"}}, seed=1)
pid = os.fork()
if pid == 0:
    _core.Run(situation.to_json(), json.dumps({}), 0)
    sitgen.generate_situation({"terrain": {"preset": "caves"}}, seed=2)
    os._exit(0)
_, status = os.waitpid(pid, 0)
sys.exit(os.waitstatus_to_exitcode(status))
"""


def test_a_process_forked_after_the_core_ran_in_parallel_can_build_runs() -> None:
    """The core's parallel loops start a pool of the forked process's own: the one it
    inherited has no threads, and waiting on it would wait for ever."""
    done = subprocess.run(
        [sys.executable, "-c", FORKED_RUN], capture_output=True, text=True, cwd=ROOT,
        timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr


def test_a_campaign_paused_now_and_then_stores_every_run(tmp_path: Path) -> None:
    """A class costing 3 ms a step while the machine pauses the campaign's processes now and
    then (SIGSTOP past the step timeout, as an overloaded or suspended VM does): an alarm that
    fires after its call returned is dropped, never raised in sitgen's own code, so every run
    is stored, whatever its outcome, and nothing ends with a traceback."""
    db = tmp_path / "paused.db"
    spec = _campaign(tmp_path, f"{CARELESS}:Costs3ms", n=6, time_limit_s=10.0)
    proc = subprocess.Popen(
        [*sitgen_command(), "campaign", str(spec), "--db", str(db), "--workers", "2"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        for _ in range(6):
            time.sleep(0.4)
            if proc.poll() is not None:
                break
            os.killpg(proc.pid, signal.SIGSTOP)
            time.sleep(1.3)
            os.killpg(proc.pid, signal.SIGCONT)
        out, err = proc.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGCONT)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode in (0, 1), out + err
    assert "Traceback" not in err, err
    assert len(_stored(db)) == 6, _stored(db)

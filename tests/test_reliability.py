"""Reliability: nothing a user or their controller does may hang sitgen, exhaust its memory, or
store a failure that is not the controller's. Each family drives the CLI as a user would, in a
child process whose memory and time are bounded here, and asserts the exit code, a one-line
message, and that stores keep every run they had."""

from __future__ import annotations

import base64
import http.client
import json
import os
import re
import resource
import shutil
import signal
import sqlite3
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import sitgen
from sitgen.controllers.proc_tasks import protocol_thread, wait_idle
from sitgen.execution.jobs import build_job, campaign_from_data, parse_campaign
from sitgen.store import Store
from tests.conftest import ROOT, Result, alive, run_cli, sitgen_command, spinning

MISBEHAVING = f"cmd:{sys.executable} {ROOT / 'tests' / 'controllers' / 'misbehaving.py'}"
PY = "python:tests.controllers.pycontrollers"
MEMORY_BYTES = 2 << 30
"""Address space a sitgen child may use: far above what any command here needs, far below what
an unbounded allocation would take."""


def run_limited(
    *args: str,
    cwd: Path | None = None,
    timeout_s: float = 120.0,
    memory_bytes: int = MEMORY_BYTES,
    file_bytes: int | None = None,
    prefix: tuple[str, ...] = (),
) -> Result:
    """Run the ``sitgen`` command with bounded memory (and file size), as a user would
    (behind ``prefix``, a command that runs it, where given)."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
        if file_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_bytes, file_bytes))

    done = subprocess.run(
        [*prefix, *sitgen_command(), *args],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
        timeout=timeout_s,
        preexec_fn=limit,
        check=False,
    )
    return Result(done.returncode, done.stdout, done.stderr)


def one_line_error(result: Result, code: int, starts: str) -> None:
    """The command failed with ``code`` and a single ``error: …`` line starting as given."""
    assert result.returncode == code, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"error: {starts}"), lines[0]


def stored_runs(db: Path) -> int:
    """Runs stored so far; 0 while a starting campaign has made the file but not its tables."""
    with sqlite3.connect(db) as con:
        if not con.execute("SELECT 1 FROM sqlite_master WHERE name = 'runs'").fetchone():
            return 0
        count: int = con.execute("SELECT count(*) FROM runs").fetchone()[0]
    return count


def edited(situation: sitgen.Situation, path: Path, edit: Callable[[dict[str, Any]], None]) -> Path:
    data = json.loads(situation.to_json())
    edit(data)
    path.write_text(json.dumps(data))
    return path


def campaign_spec(path: Path, controller: str, n: int = 3, time_limit_s: float = 5.0) -> Path:
    path.write_text(
        f'n = {n}\n[situation.terrain]\npreset = "open_field"\n'
        f"[situation.mission]\npeers_min = 0\npeers_max = 1\n"
        f"[run]\ntime_limit_s = {time_limit_s}\n[run.controller]\nname = {json.dumps(controller)}\n"
    )
    return path


# A campaign survives any controller.


@pytest.mark.parametrize(
    ("controller", "reason"),
    [
        (f"{PY}:Hangs", "did not reply within 0.2 s of processor time at 0.3 s"),
        (f"{PY}:Exits", "called sys.exit(0) at 0.3 s"),
        (f"{PY}:HardExits", "exited with code 7 at 0.3 s"),
        (f"{PY}:Segfaults", "was killed by SIGSEGV at 0.3 s"),
        (f"{MISBEHAVING} closeout", "closed its output at 0.4 s"),
        (f"{MISBEHAVING} deaf", "stopped reading its input at"),
        (f"{MISBEHAVING} hang", "did not reply within 2 s at 0.4 s; it is waiting, not computing"),
        (f"{MISBEHAVING} noflush", "did not reply within 2 s at 0.4 s; it is waiting, not comp"),
        (f"{MISBEHAVING} spin", "within 0.2 s of processor time at 0.4 s; it is computing"),
    ],
)
def test_a_controller_that_hangs_exits_or_crashes_is_that_runs_error(
    situation_file: Path, controller: str, reason: str
) -> None:
    """Each ends its run with an error that says how; one that did not reply says whether it
    is computing (a loop: its step timeout of processor time) or waiting (a reply not
    flushed, most often: the wall-clock backstop, ten step timeouts and at least 2 s)."""
    timeout = ("--step-timeout", "0.2")
    done = run_limited(
        "run", str(situation_file), "--controller", controller, *timeout, timeout_s=60
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert "outcome error" in done.stdout and reason in done.stdout, done.stdout
    checked = run_limited("check-controller", controller, *timeout, timeout_s=60)
    assert checked.returncode == 1 and "FAIL act" in checked.stdout, checked.stdout


@pytest.mark.parametrize(
    ("mode", "reason"),
    [
        ("stderrflood", "exited with code 3 on reset: 'last words before the crash'"),
        ("longline", "a line longer than 1048576 bytes"),
    ],
)
def test_a_controllers_output_is_bounded_however_much_it_writes(
    situation_file: Path, mode: str, reason: str
) -> None:
    """600 MiB of stderr or a 2 MiB line cost sitgen no more than a small bound: the last line
    of stderr is still quoted, and the run is an error, in 512 MiB of address space."""
    done = run_limited(
        "run",
        str(situation_file),
        "--controller",
        f"{MISBEHAVING} {mode}",
        memory_bytes=512 << 20,
        timeout_s=120,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert "outcome error" in done.stdout and reason in done.stdout, done.stdout + done.stderr


def test_check_controller_reports_a_program_that_ignores_end() -> None:
    done = run_limited("check-controller", f"{MISBEHAVING} ignoreend", timeout_s=60)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "FAIL close" in done.stdout and "did not exit within 1 s of `end`" in done.stdout
    good = run_limited("check-controller", f"{MISBEHAVING} good", timeout_s=60)
    assert good.returncode == 0 and "shut down on `end`" in good.stdout, good.stdout


def test_an_object_run_in_process_is_interrupted_and_may_not_exit(
    situation: sitgen.Situation,
) -> None:
    from tests.controllers.pycontrollers import Exits, Hangs

    hung = sitgen.run(situation, controller=Hangs(), time_limit=10, step_timeout_s=0.3)
    assert hung.outcome == "error", hung.reason
    assert "did not reply within 0.3 s of processor time at 0.3 s" in hung.reason, hung.reason
    exited = sitgen.run(situation, controller=Exits(), time_limit=10)
    assert exited.outcome == "error" and "called sys.exit(0) at 0.3 s" in exited.reason


def test_a_class_in_a_host_process_that_does_not_reply_is_told_computing_or_waiting(
    situation: sitgen.Situation,
) -> None:
    hangs = sitgen.run(situation, controller=f"{PY}:Hangs", time_limit=10, step_timeout_s=0.2)
    late = "did not reply within 0.2 s of processor time at 0.3 s; it is "
    assert late + "computing, not waiting for input" in hangs.reason, hangs.reason
    sleeps = sitgen.run(situation, controller=f"{PY}:Swallows", time_limit=10, step_timeout_s=0.2)
    late = "did not reply within 2 s at 0.3 s; it is "
    assert late + "waiting, not computing: on a sleep, a lock" in sleeps.reason, sleeps.reason


def test_a_class_that_loops_is_told_computing_even_when_starved_of_a_core(
    situation: sitgen.Situation,
) -> None:
    """Beside four loops a core, each in a session of its own (as other jobs of a loaded
    machine are: the scheduler shares a core out by session), the class that loops gets under
    a fifth of a core, but is runnable all the while: computing, not waiting (its run-queue
    time counts)."""
    with spinning(4 * (os.cpu_count() or 1)):
        hangs = sitgen.run(situation, controller=f"{PY}:Hangs", time_limit=10, step_timeout_s=0.3)
        sleeps = sitgen.run(
            situation, controller=f"{PY}:Swallows", time_limit=10, step_timeout_s=0.3
        )
    assert "it is computing, not waiting for input" in hangs.reason, hangs.reason
    assert "it is waiting, not computing" in sleeps.reason, sleeps.reason


def test_a_campaign_of_dying_controllers_stores_every_run_as_an_error(tmp_path: Path) -> None:
    db = tmp_path / "c.db"
    # In the pool workers a class is called in process (the fast path): an exception or a
    # timeout ends its run there; a crash, or a loop in C that no signal interrupts (the core's
    # watchdog kills its worker), has the run made again in a host process, which says why.
    late = (
        "did not reply within 1 s of processor time at 0.3 s; it is computing, not waiting for "
        "input: a loop that does not end?"
    )
    reasons = {
        "Exits": "called sys.exit(0) at 0.3 s",
        "Segfaults": "was killed by SIGSEGV at 0.3 s",
        "Hangs": late,
        "HoldsTheGil": late,
        "Swallows": (
            "did not reply within 10 s at 0.3 s; it is waiting, not computing: on a sleep, a "
            "lock or input of its own?"
        ),
        "HardExits": "exited with code 7 at 0.3 s",
    }
    for name, reason in reasons.items():
        controller = f"{PY}:{name}"
        spec = campaign_spec(tmp_path / "c.toml", controller, n=2)
        done = run_limited("campaign", str(spec), "--db", str(db), "--workers", "2")
        # Every run is stored; a campaign that tested nothing says so, and why, and fails.
        assert done.returncode == 1, done.stdout + done.stderr
        assert "every run is an error; the commonest:" in done.stderr
        assert "2 runs were errors (first run 0)" in done.stdout
        with sqlite3.connect(db) as con:
            stored = con.execute("SELECT outcome, reason FROM runs").fetchall()
        assert stored == [("error", f"controller `{controller}` {reason}")] * 2, stored
        db.unlink()
    # Of mixed runs, the good ones are stored as runs and the bad ones as errors.
    spec = campaign_spec(tmp_path / "c.toml", f"{MISBEHAVING} sometimes", n=6)
    done = run_limited("campaign", str(spec), "--db", str(db), "--workers", "2")
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as con:
        outcomes = [r[0] for r in con.execute("SELECT outcome FROM runs")]
    assert len(outcomes) == 6 and "error" in outcomes and set(outcomes) != {"error"}


def test_a_campaign_whose_every_situation_fails_to_generate_says_why(tmp_path: Path) -> None:
    spec = tmp_path / "tiny.toml"
    spec.write_text(
        '[situation.terrain]\npreset = "caves"\nwidth_m = 3.0\nheight_m = 3.0\n'
        "[situation.mission]\npeers_min = 5\npeers_max = 5\n"
    )
    db = tmp_path / "tiny.db"
    done = run_limited("campaign", str(spec), "--n", "4", "--db", str(db))
    one_line_error(done, 1, f"{db}: every run is an error; the commonest: generation failed:")
    assert "4 runs were errors (first run 0): generation failed" in done.stdout
    assert stored_runs(db) == 4


@pytest.mark.parametrize(
    ("controller", "message"),
    [
        ("turbo", "run.controller.name: unknown controller `turbo`"),
        ("python:missing_module:X", "run.controller.name: controller `python:missing_module:X` "
         "failed to load: ModuleNotFoundError"),
        ("cmd:/no/such", "run.controller.name: controller `cmd:/no/such` could not start"),
        ("python:no_class", "run.controller.name: `python:no_class`: expected python:MODULE"),
    ],
)  # fmt: skip
def test_a_campaign_with_an_unknown_controller_fails_before_any_run(
    tmp_path: Path, controller: str, message: str
) -> None:
    db = tmp_path / "c.db"
    spec = campaign_spec(tmp_path / "c.toml", controller)
    one_line_error(run_limited("campaign", str(spec), "--db", str(db)), 2, message)
    assert not db.exists(), "nothing is created"


def test_every_controller_a_campaign_can_draw_is_checked_before_any_run(tmp_path: Path) -> None:
    spec = tmp_path / "v.toml"
    spec.write_text(
        '[situation.terrain]\npreset = "open_field"\n'
        '[vary]\n"run.controller.name" = { choice = ["vo", "python:missing_module:X"] }\n'
    )
    db = tmp_path / "v.db"
    done = run_limited("campaign", str(spec), "--n", "0", "--db", str(db))
    one_line_error(done, 2, "vary.'run.controller.name'.choice: controller `python:missing_module")
    assert not db.exists()


def test_a_controller_named_in_a_situation_spec_is_checked_at_generate(tmp_path: Path) -> None:
    spec = tmp_path / "s.toml"
    spec.write_text('[terrain]\npreset = "caves"\n[mission.agent_controller]\nname = "turbo"\n')
    done = run_limited("generate", str(spec), "-o", str(tmp_path / "s.json"))
    one_line_error(done, 2, "mission.agent_controller.name: unknown controller `turbo`")


def _processes_with(marker: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and int(entry.name) != os.getpid():
            try:
                cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if marker in cmdline and alive(int(entry.name)):
                found.append(int(entry.name))
    return found


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_controllers_children_end_with_its_run(situation_file: Path, tmp_path: Path) -> None:
    pids = tmp_path / "pids"
    controller = f"{MISBEHAVING} spawn {pids}"
    done = run_limited(
        "run", str(situation_file), "--controller", controller, "--step-timeout", "0.2",
        timeout_s=60,
    )  # fmt: skip
    assert done.returncode == 1 and "did not reply within 2 s" in done.stdout, done.stdout
    child, program = (int(p) for p in pids.read_text().split())
    assert not alive(program) and not alive(child), "the program's whole group is killed"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_killing_a_campaign_outright_leaves_no_worker_or_controller(tmp_path: Path) -> None:
    db = tmp_path / "killed.db"
    # The class in a host process of its own, as a program: a `python:` class runs inside the
    # pool workers, so only a program leaves processes of its own to look for.
    start = "'from sitgen.controllers.host import main; main()'"
    host = f"cmd:{sys.executable} -c {start} tests.controllers.pycontrollers:Slow"
    spec = campaign_spec(tmp_path / "slow.toml", host, n=8, time_limit_s=60.0)
    proc = subprocess.Popen(
        [*sitgen_command(), "campaign", str(spec), "--db", str(db), "--workers", "2"],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while len(_processes_with("pycontrollers:Slow")) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert len(_processes_with("pycontrollers:Slow")) == 2, "two controllers at work"
        # The workers are forked by a server process the campaign started.
        started = [p.pid for p in psutil.Process(proc.pid).children(recursive=True)]
        servers = [p for p in started if "forkserver" in " ".join(psutil.Process(p).cmdline())]
        assert len(servers) == 3, "the fork server and the campaign's two workers"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 10
    while any(alive(p) for p in started) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(p) for p in servers), "no pool worker outlives the campaign"
    assert _processes_with("pycontrollers:Slow") == [], "no controller outlives the campaign"
    assert not any(alive(p) for p in started), "nothing the campaign started outlives it"


# Resources are bounded, up front.


def test_a_campaign_of_a_billion_runs_streams_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    db = tmp_path / "big.db"

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))

    proc = subprocess.Popen(
        [*sitgen_command(), "campaign", "--n", "1000000000", "--db", str(db), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=limit,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            time.sleep(0.5)
            if db.exists() and stored_runs(db) >= 4:
                break
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "stopped early" in out
    assert stored_runs(db) >= 4


def _png_header(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data)
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    idat = zlib.compress(b"\0" * 64)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


@pytest.mark.parametrize(
    ("name", "content", "source", "message"),
    [
        ("huge.map", b"type octile\nheight 1000000000\nwidth 1000000000\nmap\n", "map",
         "1000000000 × 1000000000 cells is more than the 100000000 a map may have"),
        ("huge.png", _png_header(100_000, 100_000), "image",
         "100000 × 100000 cells is more than the 100000000 a map may have"),
        ("huge.png", _png_header(100_000, 100_000), "map",
         "100000 × 100000 cells is more than the 100000000 a map may have"),
    ],
)  # fmt: skip
def test_map_files_claiming_huge_sizes_are_refused_before_allocating(
    tmp_path: Path, name: str, content: bytes, source: str, message: str
) -> None:
    (tmp_path / name).write_bytes(content)
    filters = '[[terrain.filters]]\nkind = "threshold"\n' if source == "image" else ""
    spec = tmp_path / "s.toml"
    spec.write_text(f'[terrain.source]\nkind = "{source}"\npath = "{name}"\n{filters}')
    done = run_limited("generate", str(spec), "-o", str(tmp_path / "s.json"))
    assert done.returncode in (1, 2) and message in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_a_map_redrawn_finer_than_the_cap_is_refused(tmp_path: Path) -> None:
    # A 200 m × 200 m map file redrawn at 1.5 cm is 1.8 × 10^8 cells; the spec's own size check
    # cannot know the file's size, so the redraw checks it.
    rows = "." * 2000 + "\n"
    (tmp_path / "m.map").write_text(f"type octile\nheight 2000\nwidth 2000\nmap\n{rows * 2000}")
    spec = tmp_path / "s.toml"
    spec.write_text(
        '[terrain]\nresolution_m = 0.015\n[terrain.source]\nkind = "map"\npath = "m.map"\n'
    )
    done = run_limited("generate", str(spec), "-o", str(tmp_path / "s.json"))
    assert done.returncode in (1, 2), done.stderr
    assert "13333 × 13333 cells is more than the 100000000 a map may have" in done.stderr


@pytest.mark.parametrize(
    ("name", "text", "expected"),
    [
        ("m.map", "type octile\nheight 1\nwidth 3\nmap\n.x.\n", "unknown character 'x'"),
        ("m.yaml", "image: m.pgm\nresolution: 0.1\noccupied_thresh: 1.5\n", "not in [0, 1]"),
        ("m.yaml", "image: m.pgm\nresolution: 0.1\noccupied_thresh: .nan\n", "NaN is not in"),
        (
            "m.yaml",
            "image: m.pgm\nresolution: 0.1\noccupied_thresh: 0.2\nfree_thresh: 0.6\n",
            "free_thresh 0.6 is above occupied_thresh 0.2",
        ),
    ],
)
def test_map_files_a_reader_cannot_trust_are_refused(
    tmp_path: Path, name: str, text: str, expected: str
) -> None:
    """Characters MovingAI does not define, and ROS thresholds outside [0, 1], NaN or inverted
    (which would make the whole map occupied), are one-line errors naming the file."""
    (tmp_path / name).write_text(text)
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 2\n255\n" + bytes([254, 0, 254, 254]))
    spec = tmp_path / "s.toml"
    spec.write_text(f'[terrain.source]\nkind = "map"\npath = "{name}"\n')
    done = run_limited("generate", str(spec), "-o", str(tmp_path / "s.json"))
    assert done.returncode in (1, 2), done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0] and name in lines[0], done.stderr


def test_a_barn_grid_larger_than_the_cap_is_refused_before_it_is_read(tmp_path: Path) -> None:
    # A sparse file whose header and length both say 10001 × 10001 cells, 2 × 10^4 over the cap.
    path = tmp_path / "huge.npy"
    header = "{'descr': '|u1', 'fortran_order': False, 'shape': (10001, 10001), }"
    header += " " * (118 - len(header)) + "\n"
    with path.open("wb") as f:
        f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode())
        f.truncate(10 + len(header) + 10001 * 10001)
    with pytest.raises(OSError) as info:
        sitgen.load_map(path)
    assert str(info.value) == (
        f"{path}: holds 100020001 cells, more than the 100000000 a map may have"
    )


def test_a_zip_bomb_map_blob_is_refused_unpacked(
    situation: sitgen.Situation, tmp_path: Path
) -> None:
    packer = zlib.compressobj(9)
    megabyte = b"\0" * (1 << 20)
    blob = b"".join(packer.compress(megabyte) for _ in range(1280)) + packer.flush()

    def bomb(data: dict[str, Any]) -> None:
        data["map"]["data"] = base64.b64encode(blob).decode()

    path = edited(situation, tmp_path / "bomb.json", bomb)
    done = run_limited("run", str(path), memory_bytes=1 << 30)
    one_line_error(done, 2, f"{path}: map.data: holds more than")


def test_too_many_steps_and_too_many_workers_are_refused(
    situation_file: Path, tmp_path: Path
) -> None:
    spec = tmp_path / "run.toml"
    spec.write_text("[sim]\ndt_s = 1e-9\n")
    done = run_limited("run", str(situation_file), "--spec", str(spec))
    one_line_error(done, 2, "run.sim.dt_s: 600 s at 0.000000001 s per step is 600000000000 steps")
    done = run_limited("campaign", "--n", "2", "--workers", "20000", "--db", str(tmp_path / "w.db"))
    one_line_error(done, 2, "--workers: 20000 is not in [1, ")
    assert not (tmp_path / "w.db").exists()


# A stored failure is a real failure.


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["robots"][0]["start"].update(x_m=1e308), "robots[0].start: (1e308, "),
        (lambda d: d["robots"][0]["start"].update(x_m=-3.0), "robots[0].start: (-3.0, "),
        (lambda d: d["robots"][1]["start"].update(d["robots"][0]["start"]),
         "robots[0].start: ("),
        (lambda d: d["robots"][0]["waypoints"].append([1e6, 3.0]),
         "robots[0].waypoints[%d]: (1000000.0, 3.0) is outside the map"),
        (lambda d: d["robots"][0].update(waypoints=[]), "robots[0].waypoints: the agent needs"),
    ],
)  # fmt: skip
def test_situations_with_robots_or_routes_where_they_cannot_be_are_refused(
    situation: sitgen.Situation,
    tmp_path: Path,
    edit: Callable[[dict[str, Any]], None],
    message: str,
) -> None:
    path = edited(situation, tmp_path / "bad.json", edit)
    if "%d" in message:
        message = message % len(situation.agent.waypoints)
    done = run_limited("run", str(path), "--allow-edited")
    one_line_error(done, 2, f"{path}: {message}")


def test_a_robot_inside_an_obstacle_is_refused(tmp_path: Path) -> None:
    s = sitgen.generate_situation({"terrain": {"preset": "caves"}}, seed=1)
    inner = np.zeros_like(s.grid.occupied)
    inner[10:-10, 10:-10] = True  # a metre from the edge: the footprint stays on the map
    occupied = np.argwhere(s.grid.occupied & inner)
    row, col = occupied[len(occupied) // 2]
    res = s.grid.resolution
    x, y = (col + 0.5) * res, (s.grid.occupied.shape[0] - row - 0.5) * res

    def into_rock(d: dict[str, Any]) -> None:
        d["robots"][0]["start"].update(x_m=float(x), y_m=float(y))

    path = edited(s, tmp_path / "rock.json", into_rock)
    done = run_limited("run", str(path), "--allow-edited")
    one_line_error(done, 2, f"{path}: robots[0].start: (")
    assert done.stderr.strip().endswith("its footprint overlaps an obstacle")


def test_a_tampered_situation_is_refused_unless_allowed(
    situation: sitgen.Situation, tmp_path: Path
) -> None:
    def nudge(d: dict[str, Any]) -> None:
        d["robots"][0]["start"]["heading_rad"] += 0.1

    path = edited(situation, tmp_path / "tampered.json", nudge)
    done = run_limited("run", str(path), "--time-limit", "5")
    one_line_error(done, 2, f"{path}: provenance.content_hash: the map and robots hash to")
    assert "--allow-edited" in done.stderr
    allowed = run_limited("run", str(path), "--time-limit", "5", "--allow-edited")
    assert allowed.returncode == 0, allowed.stderr


# Errors are one line, and nothing is created by mistake.


def test_non_utf8_files_and_non_finite_bounds_are_one_line_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_bytes(b'{"format": "\xff\xfe"}')
    one_line_error(run_limited("run", str(bad)), 2, f"{bad}: not a situation file: byte 12")
    spec = tmp_path / "bad.toml"
    spec.write_bytes(b"n = 3\n# \xff\n")
    one_line_error(run_limited("campaign", str(spec), "--db", str(tmp_path / "x.db")), 2, str(spec))
    for bound in ("nan", "inf", "-inf"):
        spec.write_text(f'[vary]\n"situation.terrain.width_m" = {{ uniform = [20.0, {bound}] }}\n')
        done = run_limited("campaign", str(spec), "--db", str(tmp_path / "x.db"))
        one_line_error(
            done, 2, "vary.'situation.terrain.width_m'.uniform: expected [lo, hi] finite"
        )
    assert not (tmp_path / "x.db").exists()


@pytest.fixture(scope="module")
def small_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("store") / "small.db"
    done = run_limited("campaign", "--n", "4", "--db", str(db), "--workers", "2")
    assert done.returncode == 0, done.stderr
    return db


def _copy(db: Path, to: Path) -> Path:
    with sqlite3.connect(db) as src, sqlite3.connect(to) as dst:
        src.backup(dst)
    return to


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("UPDATE meta SET value = 'two' WHERE key = 'schema_version'",
         "damaged store: schema_version is 'two', not a number"),
        ("DROP TABLE trajectories", "damaged store: no table trajectories"),
        ("UPDATE runs SET score = 'abc' WHERE id = 2",
         "damaged store: run 2's score is 'abc', not a number"),
    ],
)  # fmt: skip
def test_a_damaged_store_is_a_one_line_error(
    small_store: Path, tmp_path: Path, damage: str, message: str
) -> None:
    db = _copy(small_store, tmp_path / "damaged.db")
    with sqlite3.connect(db) as con:
        con.execute(damage)
    for command in ("rank", "failures", "report"):
        one_line_error(run_limited(command, str(db)), 1, f"{db}: {message}")
    resumed = run_limited("campaign", "--n", "4", "--db", str(db))
    one_line_error(resumed, 2, f"{db}: {message}")


def test_a_trajectory_that_does_not_decode_is_named(small_store: Path, tmp_path: Path) -> None:
    db = _copy(small_store, tmp_path / "damaged.db")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE trajectories SET data = x'00112233' WHERE run_id = 1")
    message = f"{db}: damaged store: run 1's trajectory does not decode"
    one_line_error(run_limited("report", str(db), "-o", str(tmp_path / "r")), 1, message)
    one_line_error(
        run_limited("show", str(db), "--run", "1", "-o", str(tmp_path / "x.png")), 1, message
    )


def test_a_breakdown_that_is_not_json_is_named(small_store: Path, tmp_path: Path) -> None:
    db = _copy(small_store, tmp_path / "damaged.db")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE runs SET breakdown = '{not json' WHERE id = 1")
    message = f"{db}: damaged store: run 1's breakdown is not JSON"
    one_line_error(run_limited("report", str(db), "-o", str(tmp_path / "r")), 1, message)


def test_runs_stored_by_an_older_sitgen_are_still_shown(small_store: Path, tmp_path: Path) -> None:
    # Before the map's edge counted as a wall, robots could be placed across it: such stored
    # runs are drawn as they were run, not refused like a situation file would be.
    db = _copy(small_store, tmp_path / "old.db")
    with sqlite3.connect(db) as con:
        (text,) = con.execute("SELECT situation FROM situations WHERE id = 0").fetchone()
        data = json.loads(text)
        data["robots"][0]["start"]["x_m"] = 0.05
        con.execute("UPDATE situations SET situation = ? WHERE id = 0", (json.dumps(data),))
    shown = run_limited("show", str(db), "--run", "0", "-o", str(tmp_path / "r.png"))
    assert shown.returncode == 0, shown.stderr
    report = run_limited("report", str(db), "-o", str(tmp_path / "report"), "--top", "4")
    assert report.returncode == 0, report.stderr


def test_a_truncated_or_foreign_file_is_a_one_line_error(small_store: Path, tmp_path: Path) -> None:
    half = tmp_path / "half.db"
    data = _copy(small_store, tmp_path / "full.db").read_bytes()
    half.write_bytes(data[: len(data) // 2])
    done = run_limited("rank", str(half))
    assert done.returncode == 1 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert done.stderr.startswith("error: "), done.stderr
    noise = tmp_path / "noise.db"
    noise.write_bytes(os.urandom(8192))
    one_line_error(run_limited("rank", str(noise)), 1, f"{noise}: not a sitgen campaign store")


def test_a_full_disk_stops_the_campaign_and_keeps_what_was_stored(tmp_path: Path) -> None:
    db = tmp_path / "full.db"
    done = run_limited("campaign", "--n", "60", "--db", str(db), file_bytes=3 << 20)
    one_line_error(done, 1, f"{db}: ")
    assert "the runs stored before are kept" in done.stderr
    with sqlite3.connect(db) as con:
        assert con.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        runs = con.execute("SELECT count(*) FROM runs").fetchone()[0]
        kept = con.execute("SELECT count(*) FROM trajectories").fetchone()[0]
    assert 0 < runs < 60 and kept == runs, "every stored run is whole"
    resumed = run_limited("campaign", "--n", "60", "--db", str(db), timeout_s=300)
    assert resumed.returncode == 0 and stored_runs(db) == 60, resumed.stderr


def test_a_full_disk_names_what_could_not_be_written(small_store: Path, tmp_path: Path) -> None:
    report = tmp_path / "report"
    done = run_limited("report", str(small_store), "-o", str(report), file_bytes=32 << 10)
    one_line_error(done, 1, f"{report}: cannot write the report: File too large")
    # (export goes through the same _writing; a store needs 32 KB for its WAL index to open,
    # more than this store's tables, so it is not exercised here.)
    # A store that could not even be made is not left behind empty.
    faults = tmp_path / "faults.db"
    done = run_limited("faults", "--budget", "2", "--db", str(faults), file_bytes=512)
    one_line_error(done, 2, f"{faults}: cannot create the store:")
    assert not list(tmp_path.glob("faults.db*"))


def test_two_campaigns_on_one_store_do_not_interleave(tmp_path: Path) -> None:
    db = tmp_path / "shared.db"
    first = subprocess.Popen(
        [*sitgen_command(), "campaign", "--n", "400", "--db", str(db), "--workers", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while not (db.exists() and stored_runs(db) > 0) and time.monotonic() < deadline:
            time.sleep(0.2)
        second = run_limited("campaign", "--n", "400", "--db", str(db))
        one_line_error(second, 2, f"{db}: another campaign is writing to this store")
    finally:
        first.send_signal(signal.SIGINT)
        first.wait(timeout=60)
    assert stored_runs(db) > 0


def test_reading_commands_refuse_a_missing_store_and_create_nothing(tmp_path: Path) -> None:
    db = tmp_path / "typo.db"
    for args in (
        ["rank", str(db)],
        ["failures", str(db)],
        ["export", str(db)],
        ["rerun", str(db), "0"],
        ["show", str(db), "--run", "0"],
        ["report", str(db)],
    ):
        one_line_error(run_limited(*args, cwd=tmp_path), 2, f"{db}: no such campaign store")
    assert not db.exists()
    folder = tmp_path / "folder.db"
    folder.mkdir()
    one_line_error(run_limited("rank", str(folder)), 2, f"{folder}: is a folder")
    done = run_limited("campaign", "--n", "1", "--db", str(folder))
    one_line_error(done, 2, f"{folder}: is a folder, not a campaign store")


def bound_by_permissions() -> tuple[str, ...]:
    """A prefix that runs a command bound by files' permission bits: nothing for a user;
    for root, ``setpriv`` without the capabilities that let root write anywhere."""
    if os.geteuid() != 0:
        return ()
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("root writes into read-only folders, and setpriv is not here to stop it")
    return (setpriv, "--bounding-set=-dac_override,-dac_read_search", "--")


def test_a_read_only_folder_for_a_new_store_is_named(tmp_path: Path) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        done = run_limited(
            "campaign", "--n", "1", "--db", str(folder / "c.db"), prefix=bound_by_permissions()
        )
        one_line_error(
            done, 2, f"{folder / 'c.db'}: cannot create the store: {folder} is read-only"
        )
    finally:
        folder.chmod(0o755)


def test_a_store_in_a_read_only_folder_is_named_not_called_garbage(tmp_path: Path) -> None:
    """SQLite writes its log beside a store even to read it: a store in a folder this user
    may not write is named as such (it was "not a sitgen campaign store"), and left as it was."""
    folder = tmp_path / "ro"
    folder.mkdir()
    db = folder / "c.db"
    assert run_limited("campaign", "--n", "2", "--db", str(db), "--reruns", "0").returncode == 0
    before = db.read_bytes()
    folder.chmod(0o555)
    try:
        for command in (("rank", str(db)), ("report", str(db), "-o", str(tmp_path / "out"))):
            done = run_limited(*command, prefix=bound_by_permissions())
            one_line_error(done, 1, f"{db}: cannot open the store: {folder} is read-only")
    finally:
        folder.chmod(0o755)
    assert db.read_bytes() == before


# The parsers never fail other than with a one-line SpecError.

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)


def _paths(tree: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path to a value in a JSON tree."""
    found = [prefix]
    if isinstance(tree, dict):
        for k, v in tree.items():
            found += _paths(v, (*prefix, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            found += _paths(v, (*prefix, i))
    return found


def _replace(tree: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    tree[path[0]] = _replace(tree[path[0]], path[1:], value)
    return tree


def _mutated(base: Any) -> st.SearchStrategy[Any]:
    paths = _paths(base)
    return st.tuples(st.sampled_from(paths), json_values).map(
        lambda pv: _replace(json.loads(json.dumps(base)), pv[0], pv[1])
    )


def _one_line_spec_error_or_ok(call: Callable[[], object]) -> None:
    try:
        call()
    except sitgen.SpecError as e:
        assert "\n" not in str(e).strip(), str(e)


FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def situation_data(situation: sitgen.Situation) -> dict[str, Any]:
    data: dict[str, Any] = json.loads(situation.to_json())
    return data


def test_fuzzed_situation_files_parse_or_name_a_field(situation_data: dict[str, Any]) -> None:
    @FUZZ
    @given(_mutated(situation_data))
    def check(data: Any) -> None:
        _one_line_spec_error_or_ok(lambda: sitgen.Situation(json.dumps(data), verify_hash=True))

    @FUZZ
    @given(st.text(max_size=300))
    def check_text(text: str) -> None:
        _one_line_spec_error_or_ok(lambda: sitgen.Situation(text))

    check()
    check_text()


def test_fuzzed_situation_specs_parse_or_name_a_field() -> None:
    base = sitgen.load_spec({"terrain": {"preset": "caves"}})

    @FUZZ
    @given(_mutated(base))
    # Found by the fuzzing: a key holding a line break, at a non-finite number.
    @example({"0\n": float("inf")})
    @example({"terrain": {"a\nb": float("nan")}})
    def check(spec: Any) -> None:
        if isinstance(spec, dict):
            _one_line_spec_error_or_ok(lambda: sitgen.load_spec(spec))

    check()


def test_fuzzed_campaign_and_run_specs_parse_or_name_a_field() -> None:
    base = parse_campaign(None).source

    @FUZZ
    @given(_mutated(base))
    def check(spec: Any) -> None:
        if isinstance(spec, dict):
            _one_line_spec_error_or_ok(lambda: build_job(campaign_from_data(spec), 0, 0))

    @FUZZ
    @given(_mutated({"time_limit_s": 600.0, "sim": {"dt_s": 0.1}, "controller": {"name": "vo"}}))
    def check_run(spec: Any) -> None:
        _one_line_spec_error_or_ok(lambda: sitgen._core.check_run_spec(json.dumps(spec)))

    check()
    check_run()


# Local servers: only this machine's browser, on the page itself, with bounded requests.


@pytest.fixture
def judging(small_store: Path, tmp_path: Path) -> Iterator[Any]:
    from sitgen.presentation.judge import JudgingServer

    server = JudgingServer(_copy(small_store, tmp_path / "judged.db"), "tester")
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server
    server.shutdown()


def _request(
    server: Any, method: str, path: str, headers: dict[str, str], body: bytes = b""
) -> tuple[int, bytes]:
    host, port = server.httpd.server_address[:2]
    connection = http.client.HTTPConnection(host, port, timeout=10)
    connection.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    for key, value in headers.items():
        connection.putheader(key, value)
    connection.endheaders(body or None)
    response = connection.getresponse()
    return response.status, response.read()


def test_the_judging_page_answers_only_its_own_host_and_origin(judging: Any) -> None:
    port = judging.httpd.server_address[1]
    own = {"Host": f"127.0.0.1:{port}"}
    status, page = _request(judging, "GET", "/", own)
    assert status == 200
    # A page elsewhere that rebinds its name to 127.0.0.1 sends its own name as Host.
    for host in (f"rebound.example:{port}", "127.0.0.1", f"127.0.0.1:{port + 1}"):
        for path in ("/", "/judgements.json", "/runs/run-0.html"):
            assert _request(judging, "GET", path, {"Host": host})[0] == 421, (host, path)
    assert _request(judging, "GET", "/", {})[0] == 421, "no Host at all"
    token = re.search(rb"name='token' value='([^']+)'", page)
    a = re.search(rb"name='a' value='(\d+)'", page)
    b = re.search(rb"name='b' value='(\d+)'", page)
    assert token and a and b
    form = b"token=%s&a=%s&b=%s&worse=a" % (token[1], a[1], b[1])
    length = {"Content-Length": str(len(form))}
    refused = [
        ({"Origin": "http://rebound.example"}, form, 403),
        ({"Sec-Fetch-Site": "cross-site"}, form, 403),
        ({"Content-Length": "abc"}, form, 400),
        ({"Content-Length": str(300 << 20)}, b"", 413),
        ({}, b"token=%s&a=99999999999999999999&b=%s&worse=a" % (token[1], b[1]), 400),
    ]
    for headers, body, code in refused:
        sent = {**own, **length, **headers}
        if body is not form and "Content-Length" not in headers:
            sent["Content-Length"] = str(len(body))
        assert _request(judging, "POST", "/judge", sent, body)[0] == code, headers
    with Store(judging.db) as store:
        assert store.judgements() == []
    origin = {"Origin": f"http://127.0.0.1:{port}", "Sec-Fetch-Site": "same-origin"}
    assert _request(judging, "POST", "/judge", {**own, **length, **origin}, form)[0] == 303
    with Store(judging.db) as store:
        assert len(store.judgements()) == 1


def test_run_ids_beyond_64_bits_are_runs_the_store_does_not_hold(
    small_store: Path, tmp_path: Path
) -> None:
    huge = str(2**64)
    for args in (
        ("rerun", str(small_store), huge),
        ("show", str(small_store), "--run", huge, "-o", str(tmp_path / "x.png")),
    ):
        one_line_error(run_limited(*args), 1, f"{small_store}: no run {huge}")
    done = run_limited("shrink", str(small_store), huge, "-o", str(tmp_path / "min.json"))
    assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and huge in done.stderr, done.stderr
    judgements = tmp_path / "j.json"
    judgements.write_text(json.dumps([{"a": 2**64, "b": 0, "worse": "a"}]))
    done = run_limited("judgements", "import", str(small_store), str(judgements))
    assert done.returncode != 0 and f"run {2**64} is not in" in done.stderr, done.stderr


def test_gym_environments_refuse_what_would_exhaust_memory_or_poison_rewards() -> None:
    from sitgen.controllers.gym import MAX_ENVS, NavigateEnv, NavigateVectorEnv

    for n in (0, MAX_ENVS + 1, 100_000, 2.5, True):
        with pytest.raises(ValueError, match="num_envs"):
            NavigateVectorEnv(num_envs=n)  # type: ignore[arg-type]
    for weight in (float("nan"), float("inf"), -1.0, "1"):
        with pytest.raises(ValueError, match="penalty_weight"):
            NavigateEnv(penalty_weight=weight)  # type: ignore[arg-type]
    env = NavigateEnv(seed=1)
    env.reset()
    for action in (np.array([0.3 + 1j, 0.0]), ["fast", "left"], [0.3, 0.0, 0.1]):
        with pytest.raises(ValueError, match="action"):
            env.step(action)  # type: ignore[arg-type]
    _, reward, *_ = env.step(np.array([0.3, 0.0], dtype=np.float32))
    assert np.isfinite(reward)


def test_a_non_finite_number_is_named_by_its_field(situation_file: Path) -> None:
    for value in ("nan", "inf"):
        done = run_limited("run", str(situation_file), "--time-limit", value)
        one_line_error(done, 2, f"run.time_limit_s: {float(value)!r} is not a finite number")
    with pytest.raises(sitgen.SpecError, match=r"run\.sim\.laser\.noise_sd_m: nan"):
        sitgen.run(str(situation_file), spec={"sim": {"laser": {"noise_sd_m": float("nan")}}})


def test_judgements_imported_twice_are_stored_once_and_deep_nesting_is_named(
    small_store: Path, tmp_path: Path
) -> None:
    db = _copy(small_store, tmp_path / "judged.db")
    source = tmp_path / "j.json"
    source.write_text(json.dumps([{"a": 0, "b": 1, "worse": "a", "at": "2026-11-25T10:00:00"}]))
    first = run_limited("judgements", "import", str(db), str(source))
    assert first.returncode == 0 and "imported 1 judgements" in first.stdout, first.stderr
    again = run_limited("judgements", "import", str(db), str(source))
    assert again.returncode == 0, again.stderr
    assert "imported 0 judgements" in again.stdout and "1 already in the store" in again.stdout
    with Store(db) as store:
        assert len(store.judgements()) == 1
    source.write_text("[" * 100_000 + "]" * 100_000)
    one_line_error(
        run_limited("judgements", "import", str(db), str(source)), 2, f"{source}: nested too deeply"
    )


def test_a_negative_top_is_refused(small_store: Path) -> None:
    done = run_limited("rank", str(small_store), "--top", "-5")
    assert done.returncode == 2 and "--top" in done.stderr, done.stderr


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_hung_stage_and_everything_it_started_end_with_the_crosscheck(
    situation: sitgen.Situation, tmp_path: Path
) -> None:
    from sitgen.controllers.stage import StageError, StageTool, run_stage

    pids = tmp_path / "pids"
    fake = tmp_path / "stage"
    # Stands in for Stage: starts a controller that outlives it, then hangs.
    fake.write_text(f"#!/bin/sh\nsleep 600 &\necho $! > {pids}\nsleep 600\n")
    fake.chmod(0o755)
    folder = tmp_path / "world"
    folder.mkdir()
    with pytest.raises(StageError, match="did not finish within 2 s"):
        run_stage(situation, {}, StageTool(fake, tmp_path), folder, timeout_s=2.0)
    child = int(pids.read_text())
    deadline = time.monotonic() + 5
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child), "the hung Stage's child still runs"


def test_a_dds_domain_lock_never_follows_a_planted_link_nor_waits_on_a_fifo(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The lock files live in the shared temp folder: a symlink planted there must not have
    its target truncated, a FIFO must not block; their domains are passed over."""
    from sitgen.controllers.ros2 import dds_domain

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    canary = tmp_path / "canary"
    canary.write_text("keep me")
    free = dds_domain.DOMAIN_IDS[-1]
    for domain in dds_domain.DOMAIN_IDS[:-1]:
        path = tmp_path / f"sitgen-ros2-domain-{domain}.lock"
        if domain % 2:
            path.symlink_to(canary)
        else:
            os.mkfifo(path)
    domain, lock = dds_domain._claim_domain()
    try:
        assert domain == free
        assert canary.read_text() == "keep me"
    finally:
        lock.close()


def test_an_output_file_that_is_the_store_or_links_to_it_is_refused_and_the_store_kept(
    tmp_path: Path,
) -> None:
    db = tmp_path / "c.db"
    assert run_cli("campaign", "--n", "2", "--db", str(db), "--reruns", "0").returncode == 0
    link = tmp_path / "link.xml"
    link.symlink_to(db)
    other = tmp_path / "other.db"
    other.write_bytes(db.read_bytes())
    sidecars = [tmp_path / f"c.db{x}" for x in ("-journal", "-wal", "-shm")]
    for option, path in [
        ("--junit", db),
        ("--summary", link),
        ("--junit", other),
        *(("--junit", s) for s in sidecars[:2]),
        ("--summary", sidecars[2]),
    ]:
        done = run_cli("campaign", "--n", "3", "--db", str(db), option, str(path))
        assert done.returncode == 2, done.stdout + done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: {option}: "), done.stderr
    with sqlite3.connect(db) as c:
        assert c.execute("SELECT count(*) FROM runs").fetchone()[0] == 2, "nothing ran, all kept"
    diff_db = tmp_path / "d.db"
    done = run_cli("diff", "--b", "vo", "--n", "1", "--db", str(diff_db), "--junit", str(db))
    assert done.returncode == 2 and "--junit: " in done.stderr, done.stderr
    assert other.read_bytes()[:16] == b"SQLite format 3\x00"


@pytest.mark.parametrize(
    "params",
    [
        {"answer_timeout_s": 1e300},
        {"answer_timeout_s": 0},
        {"answer_timeout_s": 1e-300},
        {"start_timeout_s": 1e-300},
        {"answer_timeout_s": -1.0},
        {"answer_timeout_s": float("nan")},
        {"max_missed_answers": 2.5},
        {"max_missed_answers": -1},
    ],
)
def test_a_ros2_controller_s_own_timeouts_are_bounded(params: dict[str, float]) -> None:
    """Every wait of a run has a documented maximum: a node's answer timeout and the answers it
    may miss are refused, naming the parameter, out of their ranges."""
    from sitgen.controllers.deadlines import ControllerError
    from sitgen.controllers.ros2.controller import Ros2Controller

    with pytest.raises(ControllerError, match=rf"params\.{next(iter(params))}: .* is not"):
        Ros2Controller("true", "`ros2:true`", params)


@pytest.mark.parametrize("prefix", ["cmd:", "ros2:"])
def test_a_command_line_that_does_not_parse_is_one_line_everywhere(
    situation_file: Path, tmp_path: Path, prefix: str
) -> None:
    controller = f"{prefix}python3 'oops"
    for args in (
        ("campaign", "--n", "2", "--db", str(tmp_path / "c.db"), "--controller", controller),
        ("run", str(situation_file), "--controller", controller),
        ("check-controller", controller),
    ):
        done = run_cli(*args)
        assert done.returncode in (1, 2), done.stdout + done.stderr
        assert "Traceback" not in done.stdout + done.stderr, done.stderr
        said = done.stdout + done.stderr
        assert "its command line does not parse: No closing quotation" in said, said
    spec = tmp_path / "nul.toml"
    paper = (ROOT / "examples" / "campaigns" / "paper.toml").read_text()
    spec.write_text(paper.replace('name = "snd_follow"', 'name = "cmd:a\\u0000b"'))
    done = run_cli("campaign", str(spec), "--n", "2", "--db", str(tmp_path / "n.db"))
    assert done.returncode == 2 and "holds a NUL character" in done.stderr, done.stderr


def test_a_program_killed_by_a_real_time_signal_is_named_by_it(situation_file: Path) -> None:
    """Real-time signals have no name of their own in Python's Signals: the reason must still
    be a line, not a traceback."""
    controller = "cmd:sh -c 'read line; kill -s RTMIN+6 $$'"
    done = run_limited("run", str(situation_file), "--controller", controller, timeout_s=60)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "was killed by SIGRTMIN+6 on reset" in done.stdout, done.stdout + done.stderr


def test_an_empty_file_given_as_a_store_to_read_is_refused_and_left_empty(tmp_path: Path) -> None:
    empty = tmp_path / "empty.db"
    empty.touch()
    for args in (
        ("diff", "--b", "vo", "--n", "1", "--situations", str(empty),
         "--db", str(tmp_path / "d.db")),
        ("faults", "--strategy", "stored", "--situations", str(empty), "--budget", "1",
         "--db", str(tmp_path / "f.db")),
        ("rank", str(empty)),
        ("report", str(empty), "-o", str(tmp_path / "site")),
    ):  # fmt: skip
        done = run_cli(*args)
        assert done.returncode in (1, 2), done.stdout + done.stderr
        assert "an empty file or database, not a sitgen campaign store" in done.stderr, done.stderr
        assert empty.stat().st_size == 0, args


def test_rerunning_a_run_whose_program_is_gone_says_it_could_not_run(tmp_path: Path) -> None:
    program = tmp_path / "trivial.py"
    program.write_text((ROOT / "benches" / "trivial_cmd.py").read_text())
    db = tmp_path / "c.db"
    controller = f"cmd:{sys.executable} {program}"
    done = run_cli("campaign", "--n", "1", "--db", str(db), "--reruns", "0", "-c", controller)
    assert done.returncode == 0, done.stderr
    assert run_cli("rerun", str(db), "0").returncode == 0
    program.unlink()
    again = run_cli("rerun", str(db), "0")
    assert again.returncode == 1, again.stdout + again.stderr
    assert "could not be run again: controller" in again.stdout, again.stdout
    assert "DIFFERS" not in again.stdout


@pytest.mark.parametrize("how", ["end", signal.SIGTERM, signal.SIGHUP, signal.SIGKILL])
def test_what_a_controller_started_is_gone_when_its_run_ends_however_sitgen_ends(
    situation_file: Path, tmp_path: Path, how: str | int
) -> None:
    """A helper a controller starts in a session of its own (setsid) leaves the controller's
    process group; it must still be gone after the run, and after sitgen is ended by a signal
    (even SIGKILL, which sitgen never sees: its reaper does the work)."""
    tag = f"{abs(hash((str(tmp_path), str(how)))) % 10**9 + 10**9}"
    program, started = tmp_path / "daemonizing.sh", tmp_path / "started"
    trivial = ROOT / "benches" / "trivial_cmd.py"
    program.write_text(
        f"#!/bin/sh\nsetsid sleep {tag} &\ntouch {started}\nexec {sys.executable} {trivial}\n"
    )
    program.chmod(0o755)

    def left() -> list[psutil.Process]:
        return [p for p in psutil.process_iter(["cmdline"]) if p.info["cmdline"] == ["sleep", tag]]

    limit = "5" if how == "end" else "3000"
    args = ["run", str(situation_file), "--controller", f"cmd:{program}", "--time-limit", limit]
    proc = subprocess.Popen([*sitgen_command(), *args], stdout=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while not started.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert started.exists(), "the helper never started"
        if how != "end":
            proc.send_signal(int(how))
        proc.wait(timeout=60)
        deadline = time.monotonic() + 5
        while left() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not left(), f"the helper outlived sitgen ({how})"
    finally:
        proc.kill()
        for p in left():
            p.kill()


def test_a_rosbag2_is_never_written_through_a_dangling_link(
    situation_file: Path, tmp_path: Path
) -> None:
    dangling = tmp_path / "bag"
    dangling.symlink_to(tmp_path / "nowhere" / "x")
    done = run_cli("run", str(situation_file), "--time-limit", "5", "--rosbag2", str(dangling))
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stderr.startswith(f"error: --rosbag2: {dangling} already exists"), done.stderr
    assert not (tmp_path / "nowhere").exists()


def test_a_wait_for_a_node_to_go_idle_reads_its_threads_but_not_fast_ddss_own() -> None:
    """wait_idle reads each thread's state from /proc: a busy thread of a process keeps it
    waiting to the bound, a process whose threads sleep does not; a thread named as Fast DDS
    names its own (``dds.ev.0``) is not waited for, whatever its state."""
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    asleep = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    protocol = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import ctypes; ctypes.CDLL(None).prctl(15, b'dds.ev.0')\nwhile True: pass",
        ]
    )
    try:
        time.sleep(0.3)  # every one started and in its loop or its sleep
        assert not wait_idle([busy.pid], 0.05)
        assert wait_idle([asleep.pid], 5.0)
        assert Path(f"/proc/{protocol.pid}/comm").read_text().strip() == "dds.ev.0"
        assert wait_idle([protocol.pid, asleep.pid], 5.0)
        assert protocol_thread(b"12 (dds.udp.7412) R 1") and not protocol_thread(b"3 (x) R 1")
    finally:
        for proc in (busy, asleep, protocol):
            proc.kill()
            proc.wait()

"""ROS 2: a real rclpy node, in its own process, drives the agent over DDS (``ros2:``) through a
campaign with the same results on 1 and 2 workers and on a repeat; a node that crashes, hangs
or never publishes ends only its run, as an error; every run reads back from its rosbag2
(MCAP) equal to the stored run with two independent readers (rosbags; mcap with
mcap-ros2-support). Skipped, with the reason, where the ROS 2 wheels (sitgen[ros2]) are not
installed."""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sitgen
from sitgen.controllers.deadlines import ControllerError
from sitgen.controllers.ros2 import bridge as ros2_bridge
from sitgen.controllers.ros2 import native as ros2_native
from sitgen.controllers.ros2 import tf as ros2_tf
from sitgen.controllers.ros2.bridge import ros2_available
from sitgen.controllers.ros2.controller import stop_kept_nodes
from sitgen.controllers.ros2.dds_domain import LOOPBACK_PROFILE, unconfined
from sitgen.store import Store
from sitgen.triage.recall import resimulate_checked, stored_run
from tests.conftest import ROOT, run_cli, sitgen_command

UNAVAILABLE = ros2_available()
pytestmark = pytest.mark.skipif(UNAVAILABLE is not None, reason=str(UNAVAILABLE))

FOLLOWER = f"ros2:{sys.executable} {ROOT / 'examples/ros2/follower_node.py'}"
MISBEHAVING = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/misbehaving.py'}"
RUN_COLUMNS = "id, controller, outcome, reason, score, failure_class, steps, events_sha256"


def example_campaign(folder: Path, n: int, time_limit_s: float) -> Path:
    """examples/ros2/campaign.toml with this interpreter's node, ``n`` runs and a shorter
    time limit."""
    text = (ROOT / "examples/ros2/campaign.toml").read_text()
    text = text.replace("ros2:python3 examples/ros2/follower_node.py", FOLLOWER)
    text = text.replace("n = 50", f"n = {n}").replace("120.0", f"{time_limit_s}")
    path = folder / "ros2.toml"
    path.write_text(text)
    return path


def runs(db: Path) -> list[tuple[Any, ...]]:
    with sqlite3.connect(db) as c:
        return c.execute(f"SELECT {RUN_COLUMNS} FROM runs ORDER BY id").fetchall()


@pytest.fixture(scope="module")
def ros2_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("ros2")
    spec = example_campaign(folder, 12, 30.0)
    # The campaign on 1 worker is the repeat of the one on 2, there with the node kept alive
    # across runs (test_ros2_styles.py repeats the usual node styles the same way); what is
    # done with its runs later (robustness copies, the report's bags, shrinking) keeps it alive
    # too, as its stored spec says.
    for name, workers, more in (("two", "2", ()), ("one", "1", ("--keep-alive",))):
        args = ("--db", str(folder / f"{name}.db"), "--workers", workers, "--reruns", "0")
        done = run_cli("campaign", str(spec), *args, *more, cwd=ROOT)
        assert done.returncode == 0, done.stderr
    return folder


def test_a_ros2_node_drives_a_campaign_the_same_on_2_workers_and_on_a_repeat_on_1(
    ros2_campaign: Path,
) -> None:
    two = runs(ros2_campaign / "two.db")
    assert len(two) == 12
    assert runs(ros2_campaign / "one.db") == two
    outcomes = {r[2] for r in two}
    assert "error" not in outcomes, [r[3] for r in two if r[2] == "error"][:3]
    # The node is driven, not bypassed: it moves, and its failures are classified.
    assert all(r[1] == FOLLOWER for r in two)
    assert sum(r[5] is not None for r in two) >= 5
    assert len({r[5] for r in two if r[5] is not None}) >= 2


def test_a_ros2_campaigns_runs_are_measured_reported_and_exported(
    ros2_campaign: Path, tmp_path: Path
) -> None:
    db = ros2_campaign / "one.db"
    done = run_cli("robustness", str(db), "--reruns", "4", cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert "robust" in done.stdout
    report = tmp_path / "report"
    done = run_cli("report", str(db), "-o", str(report), "--top", "3", "--rosbag2", "1", cwd=ROOT)
    assert done.returncode == 0, done.stderr
    bags = list((report / "rosbag2").iterdir())
    assert len(bags) == 1 and (bags[0] / "metadata.yaml").is_file()
    page = (report / f"{bags[0].name}.html").read_text()
    assert f"rosbag2/{bags[0].name}/metadata.yaml" in page


def run_node(situation: sitgen.Situation, mode: str) -> sitgen.RunRecord:
    return sitgen.run(
        situation, controller=f"{MISBEHAVING} {mode}", time_limit=30.0,
        params={"start_timeout_s": 5.0},
    )  # fmt: skip


@pytest.mark.parametrize(
    ("mode", "reason"),
    [
        ("crash", "exited with code 3 at 0.4 s: 'misbehaving: crashing on purpose'"),
        ("hang", "did not publish /cmd_vel for 10 control periods in a row"),
        ("silent", "never published /cmd_vel within 5 s of its first observation"),
        ("busy", "did not publish /cmd_vel for 10 control periods in a row"),
        ("busy_at_once", "never published /cmd_vel within 5 s of its first observation"),
    ],
)
def test_a_node_that_crashes_hangs_or_never_publishes_ends_its_run_as_an_error(
    situation: sitgen.Situation, mode: str, reason: str
) -> None:
    record = run_node(situation, mode)
    assert record.outcome == "error"
    assert reason in record.reason
    # A node that stops answering because it computes for ever is told from one that waits
    # for input it missed.
    busy = "; it was computing, not waiting for input: a callback that does not return"
    assert (busy in record.reason) == mode.startswith("busy"), record.reason


def test_a_node_that_crashes_ends_only_its_own_runs(tmp_path: Path) -> None:
    spec = tmp_path / "crashing.toml"
    spec.write_text(
        'n = 8\n[situation.terrain]\npreset = "open_field"\n[run]\ntime_limit_s = 10.0\n'
        f'[run.controller]\nname = "{MISBEHAVING} crash_on_even_routes"\n'
    )
    db = tmp_path / "crashing.db"
    done = run_cli("campaign", str(spec), "--db", str(db), "--workers", "2", "--reruns", "0")
    assert done.returncode == 0, done.stderr
    rows = runs(db)
    errors = [r for r in rows if r[2] == "error"]
    assert len(rows) == 8 and 0 < len(errors) < 8
    assert all("exited with code 3" in r[3] for r in errors)


# --- rosbag2 ----------------------------------------------------------------------------------


def quaternion_heading(q: Any) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def read_with_rosbags(folder: Path) -> dict[str, list[tuple[int, Any]]]:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    out: dict[str, list[tuple[int, Any]]] = {}
    with Reader(folder) as reader:
        for connection, t, raw in reader.messages():
            message = store.deserialize_cdr(raw, connection.msgtype)
            out.setdefault(connection.topic, []).append((t, message))
    return out


def read_with_mcap(folder: Path) -> dict[str, list[tuple[int, Any]]]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict[str, list[tuple[int, Any]]] = {}
    (path,) = folder.glob("*.mcap")
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append((message.log_time, decoded))
    return out


@pytest.fixture(scope="module")
def bagged(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, Path]:
    """A campaign of the built-in agent kept whole, and its top failing run as a rosbag2."""
    folder = tmp_path_factory.mktemp("bag")
    db = folder / "c.db"
    done = run_cli(
        "campaign", "--n", "12", "--seed", "3", "--db", str(db), "--reruns", "0",
        "--keep-trajectories", "all",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as c:
        (run_id,) = c.execute(
            "SELECT id FROM runs WHERE failure_class IS NOT NULL AND events_jsonl LIKE "
            "'%collision%' ORDER BY score DESC LIMIT 1"
        ).fetchone()
    bag = folder / "bag"
    done = run_cli("export", str(db), "--run", str(run_id), "--format", "rosbag2", "-o", str(bag))
    assert done.returncode == 0, done.stderr
    return db, run_id, bag


@pytest.mark.parametrize("reader", [read_with_rosbags, read_with_mcap])
def test_a_failing_runs_rosbag2_reads_back_equal_to_the_stored_run(
    bagged: tuple[Path, int, Path], reader: Any
) -> None:
    db, run_id, bag = bagged
    topics = reader(bag)
    with Store(db) as store:
        trajectory = store.trajectory(run_id)
        row = stored_run(store, run_id)
        situation, record = resimulate_checked(store, row, sensed=True)
    assert trajectory is not None and record.sensed is not None
    steps = len(trajectory)
    # Poses: the agent's odometry and every peer's transform, step by step.
    odom = topics["/odom"]
    assert len(odom) == steps
    poses = np.array(
        [
            (
                m.pose.pose.position.x,
                m.pose.pose.position.y,
                quaternion_heading(m.pose.pose.orientation),
            )
            for _, m in odom
        ]
    )
    np.testing.assert_allclose(poses[:, :2], trajectory[:, 0, :2], atol=1e-4)
    np.testing.assert_allclose(
        np.remainder(poses[:, 2] - trajectory[:, 0, 2] + np.pi, 2 * np.pi) - np.pi, 0, atol=1e-4
    )
    tf = topics["/tf"]
    for k, robot in enumerate(situation.robots[1:], start=1):
        frame = f"peer_{robot.id}/base_link"
        xs = [
            next(t.transform.translation.x for t in m.transforms if t.child_frame_id == frame)
            for _, m in tf
        ]
        np.testing.assert_allclose(xs, trajectory[:, k, 0], atol=1e-4)
    # Scans: what the controller saw, beam for beam (as float32, LaserScan's type).
    scans = np.array([np.asarray(m.ranges) for _, m in topics["/scan"]])
    np.testing.assert_array_equal(scans, record.sensed.ranges.astype(np.float32))
    assert topics["/scan"][0][1].header.frame_id == "base_scan"
    # Events: one marker array per event of the stored log, at its start, labelled.
    events = [json.loads(line) for line in row["events_jsonl"].splitlines()]
    arrays = [m for _, m in topics["/events"]]
    assert len(arrays) == len(events) > 0
    by_id = {a.markers[0].id: a.markers[0] for a in arrays}
    for n, event in enumerate(events):
        marker = by_id[n]
        assert marker.ns == event["kind"]
        stamp = marker.header.stamp.sec + marker.header.stamp.nanosec * 1e-9
        assert stamp == pytest.approx(event["start_s"], abs=1e-9)
    assert any(e["kind"] == "collision" for e in events)
    # The map, once, as ROS lays it out (row 0 at the bottom), and the agent's route.
    ((_, grid),) = topics["/map"]
    occupied = situation.grid.occupied
    assert (grid.info.height, grid.info.width) == occupied.shape
    np.testing.assert_array_equal(
        np.asarray(grid.data).reshape(occupied.shape) == 100, np.flipud(occupied)
    )
    ((_, path),) = topics["/plan"]
    assert [(p.pose.position.x, p.pose.position.y) for p in path.poses] == list(
        situation.agent.waypoints
    )


def test_the_rosbag2_has_the_metadata_ros2_bag_play_reads(bagged: tuple[Path, int, Path]) -> None:
    import yaml

    _, _, bag = bagged
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap"
    types = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["type"]
        for t in info["topics_with_message_count"]
    }
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert types["/events"] == "visualization_msgs/msg/MarkerArray"
    assert types["/cmd_vel"] == "geometry_msgs/msg/TwistStamped"
    durability = {
        t["topic_metadata"]["name"]: [
            q["durability"] for q in t["topic_metadata"]["offered_qos_profiles"]
        ]
        for t in info["topics_with_message_count"]
    }
    for topic in ("/map", "/tf_static", "/plan"):
        assert durability[topic] == ["transient_local"]
    assert durability["/scan"] == []


def test_sitgen_run_writes_a_rosbag2_of_a_ros2_nodes_run(
    situation_file: Path, tmp_path: Path
) -> None:
    bag = tmp_path / "bag"
    done = run_cli(
        "run", str(situation_file), "--controller", FOLLOWER, "--time-limit", "20",
        "--rosbag2", str(bag), cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    topics = read_with_mcap(bag)
    assert len(topics["/scan"]) == len(topics["/odom"]) == 201
    again = run_cli(
        "run", str(situation_file), "--controller", FOLLOWER, "--time-limit", "20",
        "--rosbag2", str(bag), cwd=ROOT,
    )  # fmt: skip
    assert again.returncode == 2 and "already exists" in again.stderr


def test_a_ros2_runs_failure_shrinks_and_reruns_the_same(
    ros2_campaign: Path, tmp_path: Path
) -> None:
    db = ros2_campaign / "one.db"
    with sqlite3.connect(db) as c:
        (run_id,) = c.execute(
            "SELECT id FROM runs WHERE failure_class IS NOT NULL ORDER BY score DESC LIMIT 1"
        ).fetchone()
    out = tmp_path / "min.json"
    done = run_cli(
        "shrink", str(db), str(run_id), "--max-probes", "10", "-o", str(out), "--format", "json",
        cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["probes"] > 0
    seed = result["rerun"].split("--seed ")[1]
    rerun = run_cli(
        "run", str(out), "--spec", result["run_spec"], "--seed", seed, "--json", cwd=ROOT,
    )  # fmt: skip
    assert rerun.returncode == 0, rerun.stderr
    assert json.loads(rerun.stdout)["failure"]["class"] == result["class"]


def test_diff_of_two_settings_of_a_ros2_node(ros2_campaign: Path, tmp_path: Path) -> None:
    fast = json.dumps({"name": FOLLOWER, "params": {"speed_m_s": 0.9, "stop_m": 0.2}})
    done = run_cli(
        "diff", "--a", FOLLOWER, "--b", fast, "--situations", str(ros2_campaign / "two.db"),
        "--n", "1", "--db", str(tmp_path / "d.db"), "--format", "json", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr
    report = json.loads(done.stdout)
    assert report["situations"] == 1


def test_a_diff_whose_side_keeps_its_node_alive_compares_every_situation(
    ros2_campaign: Path, tmp_path: Path
) -> None:
    """A kept alive on one worker, B another node after it: A's node is stopped before B's
    starts on the worker's domain, so B's runs are not refused as "domain not free" and every
    situation is compared."""
    kept = json.dumps({"name": FOLLOWER, "keep_alive": True})
    fast = json.dumps({"name": FOLLOWER, "params": {"speed_m_s": 0.9, "stop_m": 0.2}})
    done = run_cli(
        "diff", "--a", kept, "--b", fast, "--situations", str(ros2_campaign / "two.db"),
        "--n", "1", "--workers", "1", "--db", str(tmp_path / "d.db"), "--format", "json",
        cwd=ROOT,
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr
    report = json.loads(done.stdout)
    assert report["both_ran"] == 1, report
    assert report["b_errors"] == [] and report["not_compared"] == {"a": [], "b": []}, report


def udp_sockets(pids: set[int]) -> set[tuple[str, int]]:
    """(address, port) of every IPv4 UDP socket the processes ``pids`` hold (/proc/net/udp,
    matched by socket inode)."""
    inodes: set[str] = set()
    for pid in pids:
        with contextlib.suppress(OSError):
            for fd in Path(f"/proc/{pid}/fd").iterdir():
                with contextlib.suppress(OSError):
                    target = os.readlink(fd)
                    if target.startswith("socket:["):
                        inodes.add(target[8:-1])
    out = set()
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[9] in inodes:
            address, port = fields[1].split(":")
            octets = bytes.fromhex(address)[::-1]
            out.add((".".join(str(b) for b in octets), int(port, 16)))
    return out


def descendants(pid: int) -> set[int]:
    """``pid`` and every process below it (the node sitgen started, its reaper)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                stat = (entry / "stat").read_text()
                parents[int(entry.name)] = int(stat[stat.rindex(")") + 2 :].split()[1])
    found, frontier = {pid}, [pid]
    while frontier:
        here = frontier.pop()
        for child, parent in parents.items():
            if parent == here and child not in found:
                found.add(child)
                frontier.append(child)
    return found


def multicast_interfaces(group: str) -> set[str]:
    """The interfaces on which some socket of this machine is in ``group`` (as
    /proc/net/igmp writes it)."""
    interfaces, device = set(), ""
    for line in Path("/proc/net/igmp").read_text().splitlines()[1:]:
        if not line.startswith("\t"):
            device = line.split()[1]
        elif line.split()[0] == group:
            interfaces.add(device)
    return interfaces


def test_a_run_neither_hears_nor_is_heard_by_the_network(situation_file: Path) -> None:
    """A test run must not announce itself to, or hear from, the network: while a node drives
    a run, every UDP socket of sitgen's process and the node's is bound to 127.0.0.1 (or is
    the discovery multicast group's own socket), and no socket of this machine is in DDS's
    discovery multicast group (239.255.0.1) on any interface but the loopback. Static peers in
    the environment (here garbage) are dropped, not an error."""
    group = "0100FFEF"  # 239.255.0.1 as /proc/net/igmp writes it
    args = ["run", str(situation_file), "--controller", FOLLOWER, "--time-limit", "3000"]
    # Static peers, garbage or not, are dropped: they would reach beyond this machine.
    env = dict(os.environ, ROS_STATIC_PEERS="garbage;;::zz;192.0.2.77")
    proc = subprocess.Popen([*sitgen_command(), *args], stdout=subprocess.PIPE, text=True, env=env)
    try:
        joined: set[str] = set()
        bound: set[tuple[str, int]] = set()
        deadline = time.monotonic() + 8
        while time.monotonic() < deadline and proc.poll() is None:
            joined |= multicast_interfaces(group)
            bound |= udp_sockets(descendants(proc.pid))
            time.sleep(0.2)
        assert proc.poll() is None, "the run ended before it could be watched"
        assert joined <= {"lo"}, f"a participant joined 239.255.0.1 on {joined}"
        assert len(bound) >= 4, f"the run's DDS sockets were not seen: {bound}"
        outside = {b for b in bound if b[0] not in ("127.0.0.1", "239.255.0.1")}
        assert not outside, f"sockets bound beyond the loopback: {sorted(outside)}"
    finally:
        proc.kill()
        proc.wait()


def fast_dds_segments() -> set[str]:
    return {p.name for p in Path("/dev/shm").glob("fast*")} if Path("/dev/shm").is_dir() else set()


def test_a_node_that_dies_leaves_nothing_in_dev_shm(situation: sitgen.Situation) -> None:
    """A node that dies without closing its participant (here ``os._exit``, as a crash or
    SIGKILL would) leaves no shared-memory segment behind: sitgen's participants talk UDP on
    the loopback only."""
    before = fast_dds_segments()
    record = run_node(situation, "crash")
    assert record.outcome == "error" and "exited with code 3" in record.reason
    assert fast_dds_segments() - before == set()


def test_an_rmw_that_is_not_installed_is_refused_in_one_line(
    situation_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """rcl ends the whole process (code 102) as it loads when RMW_IMPLEMENTATION names an rmw
    that is not there; sitgen refuses it first, in one line that names the variable."""
    monkeypatch.setenv("RMW_IMPLEMENTATION", "rmw_nope")
    done = run_cli("campaign", "--n", "2", "--controller", FOLLOWER, "--db", str(tmp_path / "c.db"))
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: ") and "RMW_IMPLEMENTATION=rmw_nope is not installed" in line
    done = run_cli("run", str(situation_file), "--controller", FOLLOWER, "--time-limit", "1")
    assert "RMW_IMPLEMENTATION=rmw_nope is not installed" in done.stdout + done.stderr
    assert "Traceback" not in done.stderr and "exiting with 102" not in done.stderr


def test_run_with_a_spec_passes_its_controller_params_to_the_node(
    situation_file: Path, tmp_path: Path
) -> None:
    """``run --controller ros2:… --spec F``: the node gets F's controller params, as it does
    them given with ``--param``, and runs otherwise than on its defaults."""
    spec = tmp_path / "run.toml"
    spec.write_text(f'[controller]\nname = "{FOLLOWER}"\nparams = {{ speed_m_s = 0.1 }}\n')
    common = ("run", str(situation_file), "--controller", FOLLOWER, "--time-limit", "5", "--json")
    records = []
    for extra in ((), ("--spec", str(spec)), ("--param", "speed_m_s=0.1")):
        done = run_cli(*common, *extra)
        assert done.returncode == 0, done.stderr
        record = json.loads(done.stdout)
        records.append((record["outcome"], record["coverage"]["failure_at"], record["events"]))
    defaults, from_spec, from_param = records
    assert from_spec == from_param
    assert from_spec != defaults


def test_a_damaged_stored_run_spec_is_refused_in_one_line_and_writes_no_bag(
    bagged: tuple[Path, int, Path], tmp_path: Path
) -> None:
    """A stored run spec that is not JSON, not an object, or not a run spec: one line that
    names the run, and no bag folder left behind."""
    db, run_id, _ = bagged
    for k, damaged in enumerate(("{not json", "[]", "null", '{"controller": 5}')):
        copy = tmp_path / f"damaged{k}.db"
        copy.write_bytes(db.read_bytes())
        with sqlite3.connect(copy) as c:
            c.execute("UPDATE runs SET run_spec = ? WHERE id = ?", (damaged, run_id))
        out = tmp_path / f"bag{k}"
        done = run_cli(
            "export", str(copy), "--run", str(run_id), "--format", "rosbag2", "-o", str(out)
        )
        assert done.returncode != 0
        (line,) = done.stderr.strip().splitlines()
        assert line.startswith("error: ") and f"run {run_id}: its stored run spec" in line, line
        assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_two_exports_into_one_folder_at_once_give_one_whole_bag_and_one_refusal(
    bagged: tuple[Path, int, Path], tmp_path: Path
) -> None:
    db, run_id, first = bagged
    out = tmp_path / "bag"
    args = ["export", str(db), "--run", str(run_id), "--format", "rosbag2", "-o", str(out)]
    procs = [
        subprocess.Popen([*sitgen_command(), *args], stderr=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    results = [(p.wait(timeout=300), p.communicate()[1]) for p in procs]
    assert sorted(code for code, _ in results) == [0, 2], results
    (refusal,) = [err for code, err in results if code != 0]
    # Refused by the export's claim of the folder, or before it where the other's claim is
    # already made: either way one line.
    assert len(refusal.strip().splitlines()) == 1, refusal
    assert "is there already" in refusal or "already exists" in refusal, refusal
    assert read_with_rosbags(out).keys() == read_with_rosbags(first).keys()
    assert sorted(p.name for p in out.iterdir()) == ["bag.mcap", "metadata.yaml"]


def test_a_bag_cut_short_by_a_full_disk_is_not_left_behind(
    bagged: tuple[Path, int, Path], tmp_path: Path
) -> None:
    """A write that fails (a file size limit stands in for a full disk) leaves no partial bag
    folder, and says which one it could not write."""
    import resource

    db, run_id, _ = bagged
    out = tmp_path / "bag"

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (64 << 10, 64 << 10))

    done = subprocess.run(
        [*sitgen_command(), "export", str(db), "--run", str(run_id), "--format", "rosbag2",
         "-o", str(out)],
        capture_output=True, text=True, preexec_fn=limit, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode != 0
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: ") and str(out) in line, line
    assert list(tmp_path.iterdir()) == []


def test_a_node_sitgen_did_not_start_on_the_runs_domain_is_found_and_the_domain_passed_over(
    situation: sitgen.Situation,
) -> None:
    """A node left on the run's DDS domain by something else would answer the run as well
    (and change its score): the run errs naming that process, and the next run moves to
    another domain, where it runs clean."""
    from sitgen.controllers.ros2.dds_domain import confine, process_domain

    domain = process_domain()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    confine(env)
    # A node that says when its endpoints exist (the run then finds it as it starts).
    code = (
        "import rclpy; from geometry_msgs.msg import Twist; from sensor_msgs.msg import "
        "LaserScan; rclpy.init(); n = rclpy.create_node('stray'); "
        "n.create_publisher(Twist, '/cmd_vel', 10); "
        "n.create_subscription(LaserScan, '/scan', lambda m: None, 10); "
        "print('ready', flush=True); rclpy.spin(n)"
    )
    stray = subprocess.Popen(
        [sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True,
        stderr=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip
    try:
        assert stray.stdout is not None and stray.stdout.readline().strip() == "ready"
        record = sitgen.run(situation, controller=FOLLOWER, time_limit=5.0)
        assert record.outcome == "error"
        assert f"DDS domain {domain} is not free: process {stray.pid}," in record.reason
        assert process_domain() != domain
        record = sitgen.run(situation, controller=FOLLOWER, time_limit=5.0)
        assert record.outcome != "error", record.reason
    finally:
        stray.kill()
        stray.wait()


@pytest.mark.parametrize("strategy", ["mutation", "map-elites", "random", "coverage"])
def test_every_search_strategy_drives_a_ros2_node(strategy: str, tmp_path: Path) -> None:
    """Every strategy runs every controller kind: a search of a ros2: node on one worker (the
    case a forked pool worker once hung on) stores its runs, none in error."""
    spec = example_campaign(tmp_path, 2, 8.0)
    db = tmp_path / "search.db"
    done = run_cli(
        "search", str(spec), "--strategy", strategy, "--budget", "2", "--seed", "2",
        "--workers", "1", "--reruns", "0", "--db", str(db), cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = runs(db)
    assert len(rows) == 2 and all(r[2] != "error" for r in rows), rows


def test_a_node_reads_the_situations_map_on_map_as_a_map_server_serves_it(
    situation: sitgen.Situation, tmp_path: Path
) -> None:
    """/map is live: a node subscribed to it (transient local, as a costmap's static layer is)
    reads the situation's grid, ROS's way up (row 0 at the origin), 100 occupied, 0 free."""
    out = tmp_path / "map.json"
    node = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/map_reader.py'} {out}"
    record = sitgen.run(situation, controller=node, time_limit=1.0)
    assert record.outcome != "error", record.reason
    got = json.loads(out.read_text())
    assert_map_is(got["map"], situation)
    # The start as /initialpose, and the node's reset service called, before the run.
    assert got["initial_poses"] == [pytest.approx(start_of(situation))]
    assert got["resets"] == 1


COMPILERS = pytest.mark.skipif(
    shutil.which("gcc") is None or shutil.which("g++") is None,
    reason="sitgen builds tf2_msgs for /tf with gcc and g++, and they are not on PATH",
)


@COMPILERS
def test_a_node_reads_the_robots_pose_on_tf_and_its_laser_mount_on_tf_static(
    situation: sitgen.Situation, tmp_path: Path
) -> None:
    """/tf and /tf_static are live, read as tf2's listener reads them: odom → base_link every
    control period at the pose the robot is in at that period's start (the run's trajectory),
    map → odom (they coincide) and base_link → base_scan at the laser's mount."""
    out = tmp_path / "tf.json"
    node = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/map_reader.py'} {out}"
    spec = {
        "controller": {
            "name": node,
            # Every period answered, however loaded the machine (a held command would shift
            # the node's answers by a period, and its last transform would go unread).
            "params": {"speed_m_s": 0.4, "turn_rad_s": 0.3, "answer_timeout_s": 10.0},
        },
        "sim": {"laser": {"offset_x_m": 0.15}},
    }
    record = sitgen.run(situation, spec=spec, time_limit=3.0)
    assert record.outcome != "error", record.reason
    got = json.loads(out.read_text())
    static = {(parent, child): place for _, parent, child, *place in got["tf_static"]}
    assert static == {
        ("map", "odom"): pytest.approx([0.0, 0.0, 0.0]),
        ("base_link", "base_scan"): pytest.approx([0.15, 0.0, 0.0]),
    }
    assert {(parent, child) for _, parent, child, *_ in got["tf"]} == {("odom", "base_link")}
    dt = 0.1  # the control period: the simulator's step
    poses = {round(t / dt): place for t, _, _, *place in got["tf"]}
    trajectory = np.asarray(record.trajectory)[:, 0, :]
    assert sorted(poses) == list(range(len(trajectory) - 1))  # every period, once
    sent = np.array([poses[i] for i in sorted(poses)])
    np.testing.assert_allclose(sent[:, :2], trajectory[:-1, :2], atol=1e-9)
    turned = np.remainder(sent[:, 2] - trajectory[:-1, 2] + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(turned, 0.0, atol=1e-9)
    assert np.hypot(*(trajectory[-1, :2] - trajectory[0, :2])) > 0.5  # it drove


@COMPILERS
def test_a_node_that_listens_to_tf_is_refused_where_sitgen_cannot_publish_it(
    situation: sitgen.Situation, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where tf2_msgs cannot be had, a node that subscribes to /tf errs on start saying why
    (it would wait for transforms that never come); the build says what it lacks."""
    ros2_tf.built()  # the node's own tf2_msgs (sitgen's is what goes missing)
    bare = tmp_path / "bin"
    bare.mkdir()
    with monkeypatch.context() as m:
        m.setenv("PATH", str(bare))
        m.setenv("SITGEN_CACHE_DIR", str(tmp_path / "cache"))
        with pytest.raises(ControllerError, match="gcc and g\\+\\+ are not on PATH") as lacking:
            ros2_tf.built()
    monkeypatch.setattr(ros2_bridge, "tf_message_type", lambda: raise_(lacking.value))
    node = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/map_reader.py'} {tmp_path / 'o.json'}"
    record = sitgen.run(situation, controller=node, time_limit=1.0)
    assert record.outcome == "error"
    assert "subscribes to /tf and /tf_static, but ros2: /tf needs tf2_msgs" in record.reason


def raise_(error: Exception) -> Any:
    raise error


def dead_by(pid: int, deadline: float) -> None:
    """Wait until process ``pid`` has died (gone, or a zombie not yet reaped)."""
    while True:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[0]
        except FileNotFoundError:
            return
        if state == "Z":
            return
        assert time.monotonic() < deadline, f"process {pid} still alive"
        time.sleep(0.01)


def assert_map_is(got: dict[str, Any], situation: sitgen.Situation) -> None:
    grid = situation.grid
    rows, cols = grid.occupied.shape
    assert (got["frame"], got["width"], got["height"]) == ("map", cols, rows)
    assert got["resolution"] == pytest.approx(grid.resolution)
    data = np.asarray(got["data"]).reshape(rows, cols)
    assert set(np.unique(data)) <= {0, 100} and (data == 100).any()
    np.testing.assert_array_equal(data[::-1] == 100, grid.occupied)


def start_of(situation: sitgen.Situation) -> list[float]:
    start = situation.agent.start
    return [start.x_m, start.y_m, start.heading_rad]


def test_a_node_kept_alive_is_reset_with_each_runs_map_start_and_reset_service(
    situation: sitgen.Situation, tmp_path: Path
) -> None:
    """keep_alive: one node process for both runs, given each run's map and start and its
    reset service called before each; a run that fails stops it, and the next starts anew."""
    out = tmp_path / "kept.json"
    node = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/map_reader.py'} {out}"
    spec = {"controller": {"name": node, "keep_alive": True}}
    other = sitgen.generate_situation({"terrain": {"preset": "caves"}}, seed=4)
    try:
        for s in (situation, other):
            record = sitgen.run(s, spec=spec, time_limit=1.0)
            assert record.outcome != "error", record.reason
        got = json.loads(out.read_text())
        assert_map_is(got["map"], other)
        assert got["initial_poses"] == [
            pytest.approx(start_of(situation)),
            pytest.approx(start_of(other)),
        ]
        assert got["resets"] == 2
        # The node runs in sitgen's session (one scheduler autogroup with it: alone in a
        # session of its own it was starved of the CPU under load) and a process group of
        # its own (the terminal's Ctrl-C reaches sitgen only; the group is ended whole).
        assert os.getsid(got["pid"]) == os.getsid(0)
        assert os.getpgid(got["pid"]) == got["pid"]
        # A kept node that dies between runs is the next run's error, and the run after
        # that has a node of its own.
        os.kill(got["pid"], signal.SIGKILL)
        dead_by(got["pid"], time.monotonic() + 10.0)
        dead = sitgen.run(situation, spec=spec, time_limit=1.0)
        assert dead.outcome == "error", dead.reason
        assert "was killed by SIGKILL before its run" in dead.reason, dead.reason
        assert sitgen.run(situation, spec=spec, time_limit=1.0).outcome != "error"
        again = json.loads(out.read_text())
        assert again["pid"] != got["pid"] and again["resets"] == 1
    finally:
        stop_kept_nodes()


@pytest.fixture
def c_side(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The C hand-over on (``SITGEN_ROS2_NATIVE=1``, the default, whatever the environment
    running the tests says) for one test, and what the process remembers of it forgotten
    after, whether the test passed or not."""
    monkeypatch.setenv("SITGEN_ROS2_NATIVE", "1")
    ros2_native._native.cache_clear()
    yield
    ros2_native._native.cache_clear()


@pytest.mark.skipif(shutil.which("gcc") is None, reason="the C hand-over is built with gcc")
@pytest.mark.parametrize("style", ["scan_callback", "timer"])
def test_a_period_handed_over_in_c_gives_the_run_that_python_gives(
    style: str, situation: sitgen.Situation, monkeypatch: pytest.MonkeyPatch, c_side: None
) -> None:
    """The hand-over in C (controllers/ros2/native.py) sends what the Python one sends, in the
    same order with the same waits: a node in either usual style drives the same trajectory
    and events both ways, and the C one did hand the periods over."""
    native = ros2_native.native_period()
    assert native is not None, ros2_native.native_problem()
    calls: list[int] = []
    real = native.hand_over

    def counted(*args: Any, **kwargs: Any) -> None:
        calls.append(1)
        real(*args, **kwargs)

    monkeypatch.setattr(native, "hand_over", counted)
    node = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/usual.py'} {style}"
    in_c = sitgen.run(situation, controller=node, time_limit=8.0)
    handed = len(calls)
    assert handed > 70  # every period but the first and those that begin with a new goal
    monkeypatch.setattr(ros2_bridge, "native_period", lambda: None)
    in_python = sitgen.run(situation, controller=node, time_limit=8.0)
    assert len(calls) == handed  # none in Python
    assert in_c.outcome == in_python.outcome != "error", in_c.reason
    np.testing.assert_array_equal(np.asarray(in_c.trajectory), np.asarray(in_python.trajectory))
    assert in_c.events_jsonl == in_python.events_jsonl


def test_without_gcc_periods_are_handed_over_in_python_and_the_reason_is_kept(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, c_side: None
) -> None:
    """Where the C hand-over cannot be built (no gcc, a fresh cache), periods go through
    Python and :func:`native_problem` says why; with ``SITGEN_ROS2_NATIVE=0`` they do too."""
    bare = tmp_path / "bin"
    bare.mkdir()
    monkeypatch.setenv("PATH", str(bare))
    monkeypatch.setenv("SITGEN_CACHE_DIR", str(tmp_path / "cache"))
    assert ros2_native.native_period() is None
    assert "built with gcc, which is not on PATH" in str(ros2_native.native_problem())
    monkeypatch.setenv("SITGEN_ROS2_NATIVE", "0")
    ros2_native._native.cache_clear()
    assert ros2_native.native_problem() == "SITGEN_ROS2_NATIVE=0"


TF_TYPE = "from sitgen.controllers.ros2.tf import tf_message_type; print(tf_message_type())"


@COMPILERS
@pytest.mark.parametrize("damage", ["python", "extension"])
def test_a_damaged_tf2_msgs_build_is_built_again(tmp_path: Path, damage: str) -> None:
    """A build in the cache whose Python module does not parse, or whose extension is cut
    short: /tf's message type is built again in its place, never a traceback."""
    cache = tmp_path / "cache"
    env = {**os.environ, "SITGEN_CACHE_DIR": str(cache)}
    first = subprocess.run([sys.executable, "-c", TF_TYPE], capture_output=True, text=True,
                           env=env, timeout=300, check=False)  # fmt: skip
    assert first.returncode == 0 and "TFMessage" in first.stdout, first.stderr
    (folder,) = cache.glob("ros2-tf2-msgs-*/tf2_msgs")
    if damage == "python":
        target = folder / "msg" / "_tf_message.py"
        target.write_text("def (:\n")
    else:
        (target,) = folder.glob("*.so")
        target.write_bytes(target.read_bytes()[:100])
    again = subprocess.run([sys.executable, "-c", TF_TYPE], capture_output=True, text=True,
                           env=env, timeout=300, check=False)  # fmt: skip
    assert again.returncode == 0 and "TFMessage" in again.stdout, again.stderr
    assert again.stderr == "", again.stderr
    rebuilt = folder / target.relative_to(folder)
    assert rebuilt.stat().st_size > 100 and b"def (:" not in rebuilt.read_bytes()


def test_check_controller_says_a_users_fast_dds_profile_is_not_confined(tmp_path: Path) -> None:
    """With the user's own Fast DDS profile sitgen does not confine the run to this machine,
    and says so; with none (the loopback profile) it says nothing."""
    profile = tmp_path / "mine.xml"
    shutil.copy(LOOPBACK_PROFILE, profile)
    users = {"FASTDDS_DEFAULT_PROFILES_FILE": str(profile)}
    assert (
        unconfined({}) is None and unconfined({"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}) is None
    )
    assert unconfined(users) is not None and str(profile) in str(unconfined(users))
    env = {**os.environ, **users}
    done = subprocess.run([*sitgen_command(), "check-controller", FOLLOWER, "--steps", "5"],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=300,
                          check=False)  # fmt: skip
    assert "note network  with your Fast DDS profile" in done.stdout, done.stdout + done.stderr

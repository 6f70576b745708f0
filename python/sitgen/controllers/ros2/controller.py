"""A ROS 2 node as the agent's controller: ``ros2:COMMAND ARGS…``.

What it does: starts the node's process (``COMMAND ARGS… --ros-args -p use_sim_time:=true``,
the controller's ``params`` as ROS parameters) and stands in for the robot and its simulator
on the contract of Nav2's loopback simulator, over real DDS:

- publishes ``/clock`` (rosgraph_msgs/Clock: the node runs on simulated time), ``/scan``
  (sensor_msgs/LaserScan, frame ``base_scan``, reliable, keep last 1: a node's sensor-data
  subscription matches it, and so does one with the default QoS), ``/odom``
  (nav_msgs/Odometry, ``odom`` → ``base_link``), ``/tf`` (the same pose) and ``/tf_static``
  (``map`` → ``odom``, ``base_link`` → ``base_scan``: tf.py), the route as ``/plan``
  (nav_msgs/Path, frame ``map``), the current waypoint as ``/goal_pose``
  (geometry_msgs/PoseStamped) and ``/map`` (nav_msgs/OccupancyGrid); the route, goal and map
  are transient-local, so a node that subscribes late (with transient-local durability) still
  gets them;
- subscribes to ``/cmd_vel`` as whichever of geometry_msgs/Twist or TwistStamped (Nav2's
  default in Kilted) the node publishes there, read from the graph.

Other topic names are the node's to remap (``--ros-args -r /cmd_vel:=/my_cmd``), as with any
ROS 2 simulator. ``map`` and ``odom`` coincide (no localisation error is modelled), so a node
that needs only ``/odom`` has the robot's pose.

Why lockstep: a run's result must not depend on the machine's load. Every control period
sitgen hands the node the odometry and the scan for simulated time *t*, each once the node has
taken the one before, then the clock at the period's end (bridge.py), and waits until
the node answers with a ``/cmd_vel`` message (for TwistStamped, one not stamped before *t*);
only then does simulated time move on. A node that does not answer within
``answer_timeout_s`` — of wall time, and past it of its own processor time while it is still
at work on the period (answer_time.py: so that load cannot change which periods it answers) —
has its last command held for that period; ``max_missed_answers`` periods
in a row without an answer, a node that never publishes within the start timeout, or a node
process that exits, ends the run as an error, like any controller.

Isolation: each sitgen process talks on a DDS domain of its own (a free id claimed with a lock
file, so parallel workers and parallel campaigns never see each other), with discovery
confined to this machine (localhost discovery; for Fast DDS, UDP on 127.0.0.1 and no shared
memory: dds_domain.py).

One node across runs (the controller table's ``keep_alive = true``): the node is started
once per sitgen process (a campaign's worker) and reset between runs as Nav2's loopback
simulator resets a robot: the clock back to 0 (a node's timers on simulated time restart as
after a simulator's reset), a new ``/initialpose`` (geometry_msgs/PoseWithCovarianceStamped,
frame ``map``), ``/plan``, ``/goal_pose`` and ``/map``, and every ``std_srvs`` Trigger or Empty
service named ``reset`` or ``…/reset`` that the node offers called. Every run, a fresh node's
too, gets the same reset, so a node that resets fully runs as a fresh one would; one that does
not is refused before any run (:func:`sitgen.conformance.resets`). A run that fails stops its node.

Parameters (the spec's controller ``params``): passed to the node as ROS parameters, except
``answer_timeout_s`` (seconds, default the step timeout, 1 s: answer_time.py),
``start_timeout_s`` (wall seconds to start and answer the first observation, default 30) and
``max_missed_answers`` (periods, default 10), which are sitgen's.

Source: Nav2's loopback simulator (nav2_loopback_sim: topics, frames, stamped cmd_vel) and
REP 105 (frames); docs/ros2.md.
"""

from __future__ import annotations

import atexit
import contextlib
import math
import os
import signal
import subprocess
import threading
import time
from collections.abc import Mapping
from typing import IO, Any

from sitgen.controllers.deadlines import STEP_TIMEOUT_S, ControllerError
from sitgen.controllers.external import (
    STDERR_TAIL_BYTES,
    UserController,
    command_argv,
    program_path,
    short,
    signal_name,
)
from sitgen.controllers.marks import die_with_parent_prefix, kill_marked, marked_env, marked_pids
from sitgen.controllers.proc_tasks import BUSY_SHARE, cpu_seconds, task_state, wait_idle
from sitgen.controllers.ros2.answer_time import answered_in_time
from sitgen.controllers.ros2.bridge import LIB, Bridge, ros2_available
from sitgen.controllers.ros2.dds_domain import confine, require_free
from sitgen.controllers.ros2.messages import FRAMES, TOPICS, answer_of, stamp
from sitgen.controllers.ros2.tf import node_python_path

PREFIX = "ros2:"


NODE_START_TIMEOUT_S = 30.0
"""Wall seconds a node has to start (its process, rclpy, discovery) and to answer its first
observation: seconds on an idle machine, over 10 s (the other kinds' START_TIMEOUT_S) for a
Python node on a 2-core machine loaded three times over."""
MOST_START_TIMEOUT_S = 600.0
"""Largest ``start_timeout_s`` (wall seconds): a stack that takes longer to come up is not
coming up."""
MAX_MISSED_ANSWERS = 10
"""Control periods in a row a node may leave unanswered before its run ends as an error."""
MOST_ANSWER_TIMEOUT_S = 60.0
"""Largest ``answer_timeout_s`` (wall seconds): a node that does not answer within a minute
is not answering; every wait of a run is bounded."""
LEAST_TIMEOUT_S = 0.01
"""Smallest ``answer_timeout_s`` and ``start_timeout_s`` (wall seconds): a shorter wait than
a scheduler's time slice measures the machine, not the node, and would blame the node."""
MOST_MISSED_ANSWERS = 100_000
"""Largest ``max_missed_answers``."""
MATCH_GRACE_S = 1.0
"""Wall seconds a node that listens is given for all of its subscriptions to match."""
SETTLE_S = 0.25
"""Wall seconds a node's processes are given to go back to waiting after each message: an
idle machine needs well under a millisecond, but on a loaded one a node may wait tens of
milliseconds for a core (20 ms was missed hundreds of times in one run of the ROS 2 tests on 2
workers), and a message handed over before it has taken the last may be taken out of order.
Only a node that never sleeps waits this long, each time."""
DISCOVERY_QUIET_S = 0.15
"""Wall seconds the graph of a starting node must hold still before its first observation."""
STOP_TIMEOUT_S = 5.0
"""Wall seconds a node has to exit after SIGINT before its group is killed: ros2 launch's
(``sigterm_timeout``); a Python node tearing its participant down on a loaded machine has
taken over 2 s."""
REPEAT_S = 0.1
"""Wall seconds between repeats of the first observation until the node first answers."""
REPEATS_SETTLE_S = 2.0
"""Wall seconds a node is given, after its first answer, to go back to waiting (to have
answered every repeat of the first observation it took)."""
SITGEN_PARAMS = ("answer_timeout_s", "max_missed_answers", "start_timeout_s")
"""Controller parameters that are sitgen's, not the node's (the rest become ROS parameters)."""
CMD_VEL_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


class Ros2Controller(UserController):
    """A ROS 2 node's process, driven in lockstep through this process's :class:`Bridge`."""

    wants_map = True

    def __init__(
        self,
        command_line: str,
        name: str,
        params: Mapping[str, float] | None = None,
        step_timeout_s: float = STEP_TIMEOUT_S,
        start_timeout_s: float = NODE_START_TIMEOUT_S,
        keep_alive: bool = False,
    ) -> None:
        self.name = name
        self.keep_alive = keep_alive
        self._failed = False
        """Whether a run of this node failed: it is stopped then, never kept for the next."""
        argv = command_argv(command_line, name)
        params = dict(params or {})
        own = {k: params.pop(k) for k in SITGEN_PARAMS if k in params}
        self._answer_timeout_s = float(own.get("answer_timeout_s", step_timeout_s))
        self._start_timeout_s = float(own.get("start_timeout_s", start_timeout_s))
        for param, value, most in (
            ("answer_timeout_s", self._answer_timeout_s, MOST_ANSWER_TIMEOUT_S),
            ("start_timeout_s", self._start_timeout_s, MOST_START_TIMEOUT_S),
        ):
            if not LEAST_TIMEOUT_S <= value <= most:
                raise ControllerError(
                    f"controller {name}: params.{param}: {value!r} is not in "
                    f"[{LEAST_TIMEOUT_S:g}, {most:g}] wall seconds"
                )
        missed = own.get("max_missed_answers", MAX_MISSED_ANSWERS)
        if not (
            math.isfinite(missed) and missed == int(missed) and 0 <= missed <= MOST_MISSED_ANSWERS
        ):
            raise ControllerError(
                f"controller {name}: params.max_missed_answers: {missed!r} is not a whole "
                f"number in [0, {MOST_MISSED_ANSWERS}]"
            )
        self._max_missed = int(missed)
        ros_params = [a for k, v in sorted(params.items()) for a in ("-p", f"{k}:={v!r}")]
        self._argv = [
            program_path(argv, name),
            *argv[1:],
            "--ros-args",
            "-p",
            "use_sim_time:=true",
            *ros_params,
        ]
        self._proc: subprocess.Popen[bytes] | None = None
        self._mark = ""
        self._tail = bytearray()
        self._tail_lock = threading.Lock()
        self._bridge: Bridge | None = None
        self._subscription: Any = None
        self._stamped = False
        self._answers: list[tuple[float, float, float]] = []
        """Answers not yet read: (v, ω, stamp in seconds; 0 unstamped)."""
        self._command = (0.0, 0.0)
        self._answered_once = False
        self._missed = 0
        self._unanswered_since = (0.0, 0.0)
        """Wall time and the node's processor time when its answers stopped coming."""
        self._info: dict[str, Any] = {}
        self._goal_index = -1
        self._pids: set[int] = set()
        self._kept_as: tuple[Any, ...] | None = None

    # --- a run: start, reset, act, close ---------------------------------------------------

    def load(self) -> None:
        if self._proc is None:  # a node kept alive is loaded once
            self._bridge = self._bridge or Bridge()
            self._start()

    def reset(self, info: dict[str, Any]) -> None:
        try:
            self._reset(info)
        except ControllerError:
            self._failed = True
            raise

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        try:
            return self._act(obs)
        except ControllerError:
            self._failed = True
            raise

    def _reset(self, info: dict[str, Any]) -> None:
        self._info = info
        self._answered_once, self._missed, self._command = False, 0, (0.0, 0.0)
        self._goal_index = -1
        bridge = self._bridge = self._bridge or Bridge()
        route = [(bridge.plan, self._route(bridge, info))]
        if "map" in info:
            route.append((bridge.map, bridge.map_message(info["map"])))
        route += bridge.static_transforms(info)
        kept = self._subscription is not None  # discovered in an earlier run of this process
        if not kept:
            # Before the node starts: transient-local keeps them for it.
            bridge.hand_over(route)
            if self._proc is None:
                self._start()
            self._discover(bridge)
            route = []
        if kept:  # it may have died since its last run
            self._reap_if_exiting()
            self._check_alive("before its run")
        # The domain must hold only sitgen and what this run started (or the run errs).
        self._pids = marked_pids(self._mark)
        require_free(bridge.domain, bridge.endpoint_gids(), {os.getpid(), *self._pids})
        # The same reset for a fresh node as for one kept alive (whose simulated time starts
        # again at 0, as after a simulator's reset): a node that resets fully then runs the
        # same either way.
        restart = [(bridge.clock, bridge.clock_at(0.0))] if kept else []
        pose = [(bridge.initialpose, bridge.initial_pose(info["start"]))]
        bridge.hand_over([*restart, *route, *pose], self._settle, taken=True)
        # Part of the node's start (a fresh node's service may still be matching): its bound.
        bridge.call_resets(self.name, self._start_timeout_s, self._check_alive)
        self._answers.clear()

    def _act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        bridge = self._bridge
        assert bridge is not None
        t = float(obs["time"])
        goal = self._goal(bridge, int(obs.get("waypoints_reached", 0)), t)
        self._answers.clear()
        bridge.hand_over_period(goal, self._info, obs, t, self._pids, SETTLE_S)
        if not self._answered_once:
            self._first_answer(bridge, obs, t)
        elif answered_in_time(
            lambda s: self._await_answer(bridge, t, s),
            self._pids,
            self.name,
            t,
            self._answer_timeout_s,
        ):
            self._missed = 0
        else:
            self._missed += 1
            if self._missed == 1:
                self._unanswered_since = self._clocks()
            if self._missed >= self._max_missed:
                raise ControllerError(
                    f"controller {self.name} did not publish {TOPICS.cmd_vel} for "
                    f"{self._missed} control periods in a row at {t:.1f} s"
                    + self._busy_while_unanswered()
                )
        return self._command

    def close(self) -> str | None:
        """End the run: the node is stopped, unless it is kept alive for the next run and
        this one did not fail."""
        alive = self._proc is not None and self._proc.poll() is None
        if self.keep_alive and alive and not self._failed:
            return None
        return self.stop()

    def stop(self) -> str | None:
        """Stop the node and release sitgen's participant; None if the node exited cleanly,
        else why not."""
        if self._kept_as is not None and _KEPT.get(self._kept_as) is self:
            del _KEPT[self._kept_as]
        bridge, proc = self._bridge, self._proc
        if bridge is not None:
            bridge.shutdown()
            self._bridge, self._subscription = None, None
        unclean = None
        if proc is not None:
            # A node is asked to stop as ros2 launch asks it (SIGINT), then its group is killed.
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(timeout=STOP_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    unclean = f"did not exit within {STOP_TIMEOUT_S:g} s of SIGINT and was killed"
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            # Anything the node started that left its group (a daemon, a helper it setsid'd).
            kill_marked(self._mark)
            proc.wait()
            self._proc = None
        return unclean

    # --- the node's process ----------------------------------------------------------------

    def _start(self) -> None:
        bridge = self._bridge
        assert bridge is not None
        # One node at a time on this process's domain: a node kept alive for other runs (a
        # diff's side A, say) would talk on this one's topics, and the run would find its
        # domain not free.
        for node in [n for n in _KEPT.values() if n is not self]:
            node.stop()
        env, self._mark = marked_env()
        env.update(ROS_DOMAIN_ID=str(bridge.domain), PYTHONUNBUFFERED="1")
        confine(env)
        # The wheels' shared libraries (the rmw implementation among them) live in the
        # environment's lib/; a node started from it finds them there.
        env["LD_LIBRARY_PATH"] = os.pathsep.join(
            p for p in (LIB, env.get("LD_LIBRARY_PATH", "")) if p
        )
        # After the node's own path: a ROS install's tf2_msgs comes first where there is one.
        if (tf2_msgs := node_python_path()) is not None:
            env["PYTHONPATH"] = os.pathsep.join(
                p for p in (env.get("PYTHONPATH", ""), tf2_msgs) if p
            )
        # A process group of its own (the terminal's Ctrl-C reaches sitgen only; the group is
        # ended whole) in sitgen's session, not a session of its own: Linux's scheduler
        # autogroups are per session, and a node alone in a new one was left runnable but
        # unrun for up to 20 s of its start-up beside a busy core (2 cores, 2 busy processes),
        # long enough to miss the start timeout (docs/ros2.md, "Timing and determinism").
        try:
            self._proc = subprocess.Popen(
                [*die_with_parent_prefix(), *self._argv],
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                process_group=0,
                env=env,
            )
        except OSError as e:
            raise ControllerError(f"controller {self.name} could not start: {e}") from e
        assert self._proc.stdout is not None
        threading.Thread(target=self._drain, args=(self._proc.stdout,), daemon=True).start()

    def _drain(self, pipe: IO[bytes]) -> None:
        """Read the node's output as it comes, keeping only its tail (quoted when it dies)."""
        with contextlib.suppress(OSError, ValueError):
            while chunk := pipe.read1(1 << 16):  # type: ignore[attr-defined]
                with self._tail_lock:
                    self._tail += chunk
                    del self._tail[:-STDERR_TAIL_BYTES]

    def _reap_if_exiting(self) -> None:
        """Wait (at most 2 s) for a node whose main thread has exited while its other threads
        go down: until then it cannot be waited for, and its participant's endpoints are still
        in the graph, where it would read as a stranger on the domain."""
        proc = self._proc
        if proc is not None and task_state(f"/proc/{proc.pid}/stat") == b"Z":
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=2.0)

    def _check_alive(self, when: str) -> None:
        proc = self._proc
        if proc is None or proc.poll() is None:
            return
        code = proc.returncode
        how = f"was killed by {signal_name(-code)}" if code < 0 else f"exited with code {code}"
        time.sleep(0.05)  # the drain thread's last read
        with self._tail_lock:
            tail = self._tail.decode(errors="replace").strip().splitlines()
        said = f": {short(tail[-1])}" if tail else ""
        raise ControllerError(f"controller {self.name} {how} {when}{said}")

    # --- discovery and the exchange of one control period ----------------------------------

    def _discover(self, bridge: Bridge) -> None:
        """Wait until the node publishes /cmd_vel and listens to the scan or the odometry,
        then subscribe to /cmd_vel with the node's type."""
        deadline = time.monotonic() + self._start_timeout_s
        kind, seen = None, None
        endpoints, still_since = -1, time.monotonic()
        while True:
            self._check_alive("on start")
            kind = bridge.cmd_vel_type()
            if kind is not None and seen is None:
                seen = time.monotonic()
            # Discovery announces a node's endpoints one by one: the graph is taken as whole
            # once it has held still for DISCOVERY_QUIET_S (a subscription found after the
            # first observation would miss it, and a timer on simulated time would have
            # fired without it). The graph may still list a previous run's node for a while
            # after it has gone, so a node that listens is waited on only MATCH_GRACE_S for
            # the rest to match (the first observation is repeated until answered).
            now = time.monotonic()
            if (count := len(bridge.endpoint_gids())) != endpoints:
                endpoints, still_since = count, now
            if (
                kind is not None
                and now - still_since >= DISCOVERY_QUIET_S
                and bridge.all_matched(seen is not None and now - seen > MATCH_GRACE_S)
            ):
                break
            if time.monotonic() > deadline:
                missing = (
                    f"publish {TOPICS.cmd_vel}"
                    if kind is None
                    else f"subscribe to {TOPICS.scan} or {TOPICS.odom}"
                )
                raise ControllerError(
                    f"controller {self.name} did not {missing} within "
                    f"{self._start_timeout_s:g} s of starting"
                )
            bridge.spin(0.02)
        if (unserved := bridge.tf_unserved()) is not None:
            raise ControllerError(f"controller {self.name}: {unserved}")
        bridge.tf_read = bridge.tf is not None and bridge.node.count_subscribers(TOPICS.tf) > 0
        if kind not in CMD_VEL_TYPES:
            raise ControllerError(
                f"controller {self.name} publishes {TOPICS.cmd_vel} as {kind}; expected one of "
                + ", ".join(CMD_VEL_TYPES)
            )
        self._stamped = kind.endswith("TwistStamped")
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        msg_type = bridge.msg["TwistStamped" if self._stamped else "Twist"]
        stamped = self._stamped
        self._subscription = bridge.node.create_subscription(
            msg_type,
            TOPICS.cmd_vel,
            lambda message: self._answers.append(answer_of(message, stamped)),
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
        )
        while self._subscription.get_publisher_count() == 0:
            self._check_alive("on start")
            if time.monotonic() > deadline:
                raise ControllerError(
                    f"controller {self.name}: its {TOPICS.cmd_vel} never matched sitgen's "
                    f"subscription within {self._start_timeout_s:g} s"
                )
            bridge.spin(0.02)

    def _settle(self) -> None:
        """Wait (at most ``SETTLE_S``) until the node's processes have gone back to waiting:
        the message just acknowledged has then been taken and its callback run, before the
        next one arrives to share an executor's turn with it (where a node's callbacks would
        run in the order its subscriptions were made, not the order of arrival)."""
        wait_idle(self._pids, SETTLE_S)

    def _first_answer(self, bridge: Bridge, obs: Mapping[str, Any], t: float) -> None:
        """The first period: its observation (and the goal) is published again every
        ``REPEAT_S`` until the node answers (a subscription that discovery had not finished
        matching loses the first), within the start timeout; answers to the repeats are then
        let in and dropped, so that every later answer belongs to its own period."""
        deadline = time.monotonic() + self._start_timeout_s
        self._unanswered_since = self._clocks()
        while not self._await_answer(bridge, t, REPEAT_S):
            if time.monotonic() > deadline:
                raise ControllerError(
                    f"controller {self.name} never published {TOPICS.cmd_vel} within "
                    f"{self._start_timeout_s:g} s of its first observation"
                    + self._busy_while_unanswered()
                )
            # The goal too: a subscription that matched late (volatile) missed it.
            self._goal_index = -1
            goal = self._goal(bridge, int(obs.get("waypoints_reached", 0)), t)
            # Simulated time set back to the period's start first: a node acting on a timer on
            # simulated time acted at the first clock, and would not act again on a clock that
            # did not move (its answer lost on a writer that had not yet matched sitgen's
            # reader, or an input missed on a subscription matched late: it would never answer).
            rewind = [(bridge.clock, bridge.clock_at(t))]
            bridge.hand_over(rewind + goal + bridge.period(self._info, obs, t), self._settle)
        # A loaded node may still be answering repeats: once it has gone back to waiting,
        # every answer it will give them is on its way (one let into a later period would
        # shift every answer after it by a period).
        wait_idle(self._pids, REPEATS_SETTLE_S)
        settle = time.monotonic() + REPEAT_S
        while (left := settle - time.monotonic()) > 0:
            bridge.spin(left)
        self._answers.clear()
        self._answered_once = True

    def _clocks(self) -> tuple[float, float]:
        """Wall time and the processor time the node's processes have used."""
        return time.monotonic(), cpu_seconds(self._pids)

    def _busy_while_unanswered(self) -> str:
        """What an error for a node that stopped answering adds when the node kept a core busy
        meanwhile: it was not waiting for input (a node that misses its messages idles).
        Measured, but not quoted: a run's stored reason is the same every time it ends so."""
        (now, cpu_now), (then, cpu_then) = self._clocks(), self._unanswered_since
        wall, cpu = now - then, cpu_now - cpu_then
        if cpu < BUSY_SHARE * wall:
            return ""
        return (
            "; it was computing, not waiting for input: a callback that does not return, or an "
            'executor that spins without running callbacks? (docs/ros2.md, "A node that does '
            'not answer")'
        )

    def _await_answer(self, bridge: Bridge, t: float, timeout_s: float) -> bool:
        """Spin until the node answers the period at ``t``; False if it did not in time."""
        deadline = time.monotonic() + timeout_s
        while True:
            while self._answers:
                v, omega, stamped_at = self._answers.pop(0)
                if 0.0 < stamped_at < t - 1e-9:
                    continue  # an answer to an earlier period, arriving late (0: unstamped)
                if not (math.isfinite(v) and math.isfinite(omega)):
                    raise ControllerError(
                        f"controller {self.name} published a non-finite command ({v}, {omega}) "
                        f"at {t:.1f} s"
                    )
                self._command = (v, omega)
                return True
            self._check_alive(f"at {t:.1f} s")
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            taken = bridge.take_answer(self._subscription, self._stamped, min(left, 0.1))
            if taken is not None:
                self._answers.append(taken)

    # --- messages ---------------------------------------------------------------------------

    def _route(self, bridge: Bridge, info: Mapping[str, Any]) -> Any:
        path = bridge.msg["Path"]()
        path.header.frame_id = FRAMES.map
        path.header.stamp = stamp(bridge.msg, 0.0)
        path.poses = [self._pose(bridge, w, 0.0) for w in info["waypoints"]]
        return path

    def _goal(self, bridge: Bridge, index: int, t: float) -> list[tuple[Any, Any]]:
        """The goal to hand over before the period at ``t``: the waypoint ``index`` when it
        is a new one."""
        waypoints = self._info.get("waypoints") or []
        index = min(index, len(waypoints) - 1)
        if index == self._goal_index or index < 0:
            return []
        self._goal_index = index
        return [(bridge.goal, self._pose(bridge, waypoints[index], t))]

    def _pose(self, bridge: Bridge, point: Any, t: float) -> Any:
        pose = bridge.msg["PoseStamped"]()
        pose.header.frame_id = FRAMES.map
        pose.header.stamp = stamp(bridge.msg, t)
        pose.pose.position.x, pose.pose.position.y = float(point[0]), float(point[1])
        pose.pose.orientation.w = 1.0
        return pose


_KEPT: dict[tuple[Any, ...], Ros2Controller] = {}
"""The nodes kept alive in this process, by command line, parameters and step timeout."""


def kept_node(
    command_line: str, name: str, params: Mapping[str, float] | None, step_timeout_s: float
) -> Ros2Controller:
    """The node ``command_line`` with ``params`` kept alive in this process (``keep_alive``),
    started for its first run: a run of another node, or of the same with other parameters,
    gets a node of its own."""
    key = (command_line, tuple(sorted((params or {}).items())), step_timeout_s)
    node = _KEPT.get(key)
    if node is None:
        node = Ros2Controller(command_line, name, params, step_timeout_s, keep_alive=True)
        node._kept_as = key
        _KEPT[key] = node
    return node


@atexit.register
def stop_kept_nodes() -> None:
    """Stop every node kept alive in this process (at its exit, and where a check is done
    with them)."""
    for node in list(_KEPT.values()):
        node.stop()
    _KEPT.clear()


def check_ros2_name(name: str) -> None:
    """Check before any run that a ``ros2:`` controller can be used: the wheels import and the
    program exists. Raises ControllerError with the reason."""
    program_path(command_argv(name.removeprefix(PREFIX), f"`{name}`"), f"`{name}`")
    reason = ros2_available()
    if reason is not None:
        raise ControllerError(f"controller `{name}`: {reason}")

"""A ROS 2 node as the agent's controller: ``ros2:COMMAND ARGS…``.

What it does: starts the node's process (``COMMAND ARGS… --ros-args -p use_sim_time:=true``,
the controller's ``params`` as ROS parameters) and stands in for the robot and its simulator
on the contract of Nav2's loopback simulator, over real DDS:

- publishes ``/clock`` (rosgraph_msgs/Clock: the node runs on simulated time),
  ``/scan`` (sensor_msgs/LaserScan, frame ``base_scan``, sensor-data QoS: best effort, keep
  last 5, as ROS 2 laser drivers publish), ``/odom`` (nav_msgs/Odometry, ``odom`` →
  ``base_link``), the route as ``/plan`` (nav_msgs/Path, frame ``map``) and the current
  waypoint as ``/goal_pose`` (geometry_msgs/PoseStamped); the last two are transient-local, so a
  node that subscribes late (with transient-local durability) still gets them;
- subscribes to ``/cmd_vel`` as whichever of geometry_msgs/Twist or TwistStamped (Nav2's
  default in Kilted) the node publishes there, read from the graph.

Other topic names are the node's to remap (``--ros-args -r /cmd_vel:=/my_cmd``), as with any
ROS 2 simulator. ``map`` and ``odom`` coincide (no localisation error is modelled), so a node
that needs only ``/odom`` has the robot's pose; no ``/tf`` is published while a run is live (no
tf2_msgs wheel exists for pip; the rosbag2 export carries it).

Why lockstep: a run's result must not depend on the machine's load. Every control period
sitgen publishes the odometry, the scan and then the clock for simulated time *t*, and waits
until the node answers with a ``/cmd_vel`` message (for TwistStamped, one not stamped before
*t*); only then does simulated time move on. A node that does not answer within
``answer_timeout_s`` of wall time has its last command held for that period (the only way
machine load can reach a result, so the timeout is generous); ``max_missed_answers`` periods
in a row without an answer, a node that never publishes within the start timeout, or a node
process that exits, ends the run as an error, like any controller.

Isolation: each sitgen process talks on a DDS domain of its own (a free id claimed with a lock
file, so parallel workers and parallel campaigns never see each other), with discovery
confined to this machine (localhost discovery; for Fast DDS, UDP on 127.0.0.1 and no shared
memory: dds_domain.py).

Parameters (the spec's controller ``params``): passed to the node as ROS parameters, except
``answer_timeout_s`` (wall seconds, default the step timeout, 1 s) and ``max_missed_answers``
(periods, default 10), which are sitgen's.

Source: Nav2's loopback simulator (nav2_loopback_sim: topics, frames, stamped cmd_vel) and
REP 105 (frames); docs/ros2.md.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import IO, Any

from sitgen.controllers.dds_domain import (
    confine,
    process_domain,
    require_free,
    rmw_problem,
)
from sitgen.controllers.external import (
    START_TIMEOUT_S,
    STDERR_TAIL_BYTES,
    STEP_TIMEOUT_S,
    ControllerError,
    UserController,
    command_argv,
    die_with_parent_prefix,
    kill_marked,
    marked_env,
    marked_pids,
    program_path,
    short,
    signal_name,
)

PREFIX = "ros2:"


@dataclass(frozen=True)
class Topics:
    """sitgen's side of the contract (a node remaps its own names to these)."""

    clock: str = "/clock"
    scan: str = "/scan"
    odom: str = "/odom"
    plan: str = "/plan"
    goal: str = "/goal_pose"
    cmd_vel: str = "/cmd_vel"


@dataclass(frozen=True)
class Frames:
    """REP 105 frame ids, as Nav2's loopback simulator names them."""

    map: str = "map"
    odom: str = "odom"
    base: str = "base_link"
    scan: str = "base_scan"


TOPICS = Topics()
FRAMES = Frames()
MAX_MISSED_ANSWERS = 10
"""Control periods in a row a node may leave unanswered before its run ends as an error."""
MOST_ANSWER_TIMEOUT_S = 60.0
"""Largest ``answer_timeout_s`` (wall seconds): a node that does not answer within a minute
is not answering; every wait of a run is bounded."""
MOST_MISSED_ANSWERS = 100_000
"""Largest ``max_missed_answers``."""
MATCH_GRACE_S = 0.3
"""Wall seconds a node that listens is given for all of its subscriptions to match."""
REPEAT_S = 0.1
"""Wall seconds between repeats of the first observation until the node first answers."""
LIB = os.path.join(sys.prefix, "lib")
"""Where the ROS 2 wheels put their shared libraries (the rmw implementations among them)."""
SITGEN_PARAMS = ("answer_timeout_s", "max_missed_answers")
"""Controller parameters that are sitgen's, not the node's (the rest become ROS parameters)."""
CMD_VEL_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


def ros2_available() -> str | None:
    """None if rclpy and the messages import, else why not (one line)."""
    # rcl checks RMW_IMPLEMENTATION as its library loads and ends the whole process (code 102)
    # when it names an rmw that is not there: checked before rclpy is imported.
    problem = rmw_problem(os.environ, [LIB])
    if problem is not None:
        return problem
    try:
        _messages()
    except ImportError as e:
        return f"the ROS 2 wheels do not import ({e}); pip install 'sitgen[ros2]'"
    return None


def _messages() -> Any:
    # rclpy and the message packages are an optional extra (sitgen[ros2]): imported when a
    # ros2: controller is first used, never by sitgen's other commands.
    import rclpy  # noqa: F401
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
    from nav_msgs.msg import Odometry, Path
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import LaserScan

    return {
        "PoseStamped": PoseStamped,
        "Twist": Twist,
        "TwistStamped": TwistStamped,
        "Odometry": Odometry,
        "Path": Path,
        "Clock": Clock,
        "LaserScan": LaserScan,
        "Time": Time,
    }


def sec_nanosec(t: float) -> tuple[int, int]:
    """Simulated time ``t`` seconds as a ROS time's (sec, nanosec), exact to the nanosecond."""
    ns = round(t * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


def stamp(msg: dict[str, Any], t: float) -> Any:
    """A builtin_interfaces/Time for simulated time ``t`` (``msg``: the message types)."""
    sec, nanosec = sec_nanosec(t)
    return msg["Time"](sec=sec, nanosec=nanosec)


def quaternion(heading: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``heading`` about z."""
    return (0.0, 0.0, math.sin(heading / 2), math.cos(heading / 2))


class Bridge:
    """sitgen's side of one run: a ROS 2 context on this process's domain, the simulator's
    node with its publishers, and an executor. A fresh one per run: a participant that has
    seen a node die keeps its locators for seconds, and a new node on the same ports would
    wait that long to be discovered."""

    def __init__(self) -> None:
        reason = ros2_available()
        if reason is not None:
            raise ControllerError(f"ros2: {reason}")
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import (
            DurabilityPolicy,
            QoSProfile,
            ReliabilityPolicy,
            qos_profile_sensor_data,
        )

        self.msg = _messages()
        # sitgen's own participant is held to this machine as the node is: a test run must
        # not announce itself to, or hear from, the network (rcl reads these at init).
        confine(os.environ)
        self.domain = process_domain()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        self.node = rclpy.create_node("sitgen_sim", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        m = self.msg
        self.clock = self.node.create_publisher(m["Clock"], TOPICS.clock, reliable)
        self.scan = self.node.create_publisher(m["LaserScan"], TOPICS.scan, qos_profile_sensor_data)
        self.odom = self.node.create_publisher(m["Odometry"], TOPICS.odom, reliable)
        self.plan = self.node.create_publisher(m["Path"], TOPICS.plan, latched)
        self.goal = self.node.create_publisher(m["PoseStamped"], TOPICS.goal, latched)

    def spin(self, timeout_s: float) -> None:
        self.executor.spin_once(timeout_sec=max(0.0, timeout_s))

    def all_matched(self, listening_will_do: bool = False) -> bool:
        """Whether the node listens to the scan or the odometry, and (unless
        ``listening_will_do``) every subscription to sitgen's topics that discovery has seen
        is matched by sitgen's publisher (so the first observation is not lost to a
        half-finished discovery)."""
        publishers = (self.clock, self.scan, self.odom, self.plan, self.goal)
        listening = self.scan.get_subscription_count() + self.odom.get_subscription_count()
        return listening > 0 and (
            listening_will_do
            or all(
                p.get_subscription_count() >= self._subscriptions_seen(p.topic_name)
                for p in publishers
            )
        )

    def _subscriptions_seen(self, topic: str) -> int:
        me = self.node.get_name()
        return sum(1 for i in self.node.get_subscriptions_info_by_topic(topic) if i.node_name != me)

    def endpoint_gids(self) -> list[bytes]:
        """The GUIDs of every other endpoint on the run's topics: /cmd_vel's publishers and
        the readers of what sitgen publishes."""
        me = self.node.get_name()
        infos = [
            *self.node.get_publishers_info_by_topic(TOPICS.cmd_vel),
            *(
                i
                for p in (self.clock, self.scan, self.odom, self.plan, self.goal)
                for i in self.node.get_subscriptions_info_by_topic(p.topic_name)
            ),
        ]
        return [bytes(i.endpoint_gid) for i in infos if i.node_name != me]

    def cmd_vel_type(self) -> str | None:
        """The type a node publishes ``/cmd_vel`` as, once one is discovered."""
        for info in self.node.get_publishers_info_by_topic(TOPICS.cmd_vel):
            if info.node_name != self.node.get_name():
                return str(info.topic_type)
        return None

    def shutdown(self) -> None:
        with contextlib.suppress(Exception):
            self.executor.shutdown(timeout_sec=0)
            self.node.destroy_node()
            self.context.try_shutdown()


class Ros2Controller(UserController):
    """A ROS 2 node's process, driven in lockstep through this process's :class:`Bridge`."""

    def __init__(
        self,
        command_line: str,
        name: str,
        params: Mapping[str, float] | None = None,
        step_timeout_s: float = STEP_TIMEOUT_S,
        start_timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        self.name = name
        argv = command_argv(command_line, name)
        params = dict(params or {})
        own = {k: params.pop(k) for k in SITGEN_PARAMS if k in params}
        self._answer_timeout_s = float(own.get("answer_timeout_s", step_timeout_s))
        if not 0 < self._answer_timeout_s <= MOST_ANSWER_TIMEOUT_S:
            raise ControllerError(
                f"controller {name}: params.answer_timeout_s: {self._answer_timeout_s!r} is not "
                f"in (0, {MOST_ANSWER_TIMEOUT_S:g}] wall seconds"
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
        self._start_timeout_s = start_timeout_s
        self._proc: subprocess.Popen[bytes] | None = None
        self._mark = ""
        self._tail = bytearray()
        self._tail_lock = threading.Lock()
        self._bridge: Bridge | None = None
        self._subscription: Any = None
        self._stamped = False
        self._answers: list[Any] = []
        self._command = (0.0, 0.0)
        self._answered_once = False
        self._missed = 0
        self._info: dict[str, Any] = {}
        self._goal_index = -1

    # --- a run: start, reset, act, close ---------------------------------------------------

    def load(self) -> None:
        self._bridge = Bridge()
        self._start()

    def reset(self, info: dict[str, Any]) -> None:
        self._info = info
        bridge = self._bridge = self._bridge or Bridge()
        # The route goes out before the node starts: transient-local keeps it for the node.
        self._publish_route(bridge, info)
        if self._proc is None:
            self._start()
        self._discover(bridge)
        # The domain must hold only sitgen and what this run started (or the run errs).
        require_free(bridge.domain, bridge.endpoint_gids(), {os.getpid(), *marked_pids(self._mark)})

    def act(self, obs: Mapping[str, Any]) -> tuple[float, float]:
        bridge = self._bridge
        assert bridge is not None
        t = float(obs["time"])
        self._publish_goal(bridge, int(obs.get("waypoints_reached", 0)), t)
        self._answers.clear()
        self._publish_observation(bridge, obs, t)
        if not self._answered_once:
            self._first_answer(bridge, obs, t)
        elif self._await_answer(bridge, t, self._answer_timeout_s):
            self._missed = 0
        else:
            self._missed += 1
            if self._missed >= self._max_missed:
                raise ControllerError(
                    f"controller {self.name} did not publish {TOPICS.cmd_vel} for "
                    f"{self._missed} control periods in a row at {t:.1f} s"
                )
        return self._command

    def close(self) -> str | None:
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
                    proc.wait(timeout=2.0)
                except subprocess.TimeoutExpired:
                    unclean = "did not exit within 2 s of SIGINT and was killed"
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
        env, self._mark = marked_env()
        env.update(ROS_DOMAIN_ID=str(bridge.domain), PYTHONUNBUFFERED="1")
        confine(env)
        # The wheels' shared libraries (the rmw implementation among them) live in the
        # environment's lib/; a node started from it finds them there.
        env["LD_LIBRARY_PATH"] = os.pathsep.join(
            p for p in (LIB, env.get("LD_LIBRARY_PATH", "")) if p
        )
        try:
            self._proc = subprocess.Popen(
                [*die_with_parent_prefix(), *self._argv],
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
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
        while True:
            self._check_alive("on start")
            kind = bridge.cmd_vel_type()
            if kind is not None and seen is None:
                seen = time.monotonic()
            # The graph may still list a previous run's node for a while after it has gone,
            # so a node that listens is waited on only MATCH_GRACE_S for the rest to match
            # (the first observation is repeated until answered, which covers a late match).
            if kind is not None and bridge.all_matched(
                seen is not None and time.monotonic() - seen > MATCH_GRACE_S
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
        if kind not in CMD_VEL_TYPES:
            raise ControllerError(
                f"controller {self.name} publishes {TOPICS.cmd_vel} as {kind}; expected one of "
                + ", ".join(CMD_VEL_TYPES)
            )
        self._stamped = kind.endswith("TwistStamped")
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        msg_type = bridge.msg["TwistStamped" if self._stamped else "Twist"]
        self._subscription = bridge.node.create_subscription(
            msg_type,
            TOPICS.cmd_vel,
            self._answers.append,
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

    def _first_answer(self, bridge: Bridge, obs: Mapping[str, Any], t: float) -> None:
        """The first period: its observation is published again every ``REPEAT_S`` until the
        node answers (a subscription that discovery had not finished matching loses the
        first), within the start timeout; answers to the repeats are then let in and
        dropped, so that every later answer belongs to its own period."""
        deadline = time.monotonic() + self._start_timeout_s
        while not self._await_answer(bridge, t, REPEAT_S):
            if time.monotonic() > deadline:
                raise ControllerError(
                    f"controller {self.name} never published {TOPICS.cmd_vel} within "
                    f"{self._start_timeout_s:g} s of its first observation"
                )
            self._publish_observation(bridge, obs, t)
        settle = time.monotonic() + REPEAT_S
        while (left := settle - time.monotonic()) > 0:
            bridge.spin(left)
        self._answers.clear()
        self._answered_once = True

    def _await_answer(self, bridge: Bridge, t: float, timeout_s: float) -> bool:
        """Spin until the node answers the period at ``t``; False if it did not in time."""
        deadline = time.monotonic() + timeout_s
        when = f"at {t:.1f} s"
        while True:
            while self._answers:
                message = self._answers.pop(0)
                twist = message.twist if self._stamped else message
                stamped_at = _seconds(message.header.stamp) if self._stamped else 0.0
                if 0.0 < stamped_at < t - 1e-9:
                    continue  # an answer to an earlier period, arriving late (0: unstamped)
                v, omega = float(twist.linear.x), float(twist.angular.z)
                if not (math.isfinite(v) and math.isfinite(omega)):
                    raise ControllerError(
                        f"controller {self.name} published a non-finite command ({v}, {omega}) "
                        f"{when}"
                    )
                self._command = (v, omega)
                return True
            self._check_alive(when)
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            bridge.spin(min(left, 0.1))

    # --- messages ---------------------------------------------------------------------------

    def _publish_route(self, bridge: Bridge, info: Mapping[str, Any]) -> None:
        path = bridge.msg["Path"]()
        path.header.frame_id = FRAMES.map
        path.header.stamp = stamp(bridge.msg, 0.0)
        path.poses = [self._pose(bridge, w, 0.0) for w in info["waypoints"]]
        bridge.plan.publish(path)
        self._goal_index = -1

    def _publish_goal(self, bridge: Bridge, index: int, t: float) -> None:
        waypoints = self._info.get("waypoints") or []
        index = min(index, len(waypoints) - 1)
        if index == self._goal_index or index < 0:
            return
        self._goal_index = index
        bridge.goal.publish(self._pose(bridge, waypoints[index], t))

    def _pose(self, bridge: Bridge, point: Any, t: float) -> Any:
        pose = bridge.msg["PoseStamped"]()
        pose.header.frame_id = FRAMES.map
        pose.header.stamp = stamp(bridge.msg, t)
        pose.pose.position.x, pose.pose.position.y = float(point[0]), float(point[1])
        pose.pose.orientation.w = 1.0
        return pose

    def _publish_observation(self, bridge: Bridge, obs: Mapping[str, Any], t: float) -> None:
        m = bridge.msg
        now = stamp(m, t)
        odom = m["Odometry"]()
        odom.header.stamp, odom.header.frame_id, odom.child_frame_id = (
            now,
            FRAMES.odom,
            FRAMES.base,
        )
        x, y, heading = (float(c) for c in obs["pose"])
        odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
        q = odom.pose.pose.orientation
        q.x, q.y, q.z, q.w = quaternion(heading)
        v, omega = (float(c) for c in obs["velocity"])
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = v, omega
        bridge.odom.publish(odom)
        bridge.scan.publish(laser_scan(m, self._info, obs["ranges"], t))
        clock = m["Clock"]()
        clock.clock = now
        bridge.clock.publish(clock)


def laser_scan(msg: dict[str, Any], info: Mapping[str, Any], ranges: Any, t: float) -> Any:
    """A sensor_msgs/LaserScan of ``ranges`` at simulated time ``t``, for the laser that the
    run's reset info describes (``laser``: ``angles``, ``range_m``, ``min_range_m``)."""
    laser, angles = info["laser"], info["laser"]["angles"]
    scan = msg["LaserScan"]()
    scan.header.stamp, scan.header.frame_id = stamp(msg, t), FRAMES.scan
    scan.angle_min, scan.angle_max = float(angles[0]), float(angles[-1])
    scan.angle_increment = (
        float((angles[-1] - angles[0]) / (len(angles) - 1)) if len(angles) > 1 else 0.0
    )
    scan.time_increment = 0.0
    scan.scan_time = float(info.get("control_period_s", info.get("dt_s", 0.1)))
    scan.range_min = float(laser.get("min_range_m", 0.0))
    scan.range_max = float(laser["range_m"])
    scan.ranges = [float(r) for r in ranges]
    return scan


def _seconds(time_msg: Any) -> float:
    return float(time_msg.sec) + float(time_msg.nanosec) * 1e-9


def check_ros2_name(name: str) -> None:
    """Check before any run that a ``ros2:`` controller can be used: the wheels import and the
    program exists. Raises ControllerError with the reason."""
    program_path(command_argv(name.removeprefix(PREFIX), f"`{name}`"), f"`{name}`")
    reason = ros2_available()
    if reason is not None:
        raise ControllerError(f"controller `{name}`: {reason}")

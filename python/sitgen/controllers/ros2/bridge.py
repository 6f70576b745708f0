"""sitgen's side of a ``ros2:`` run over DDS (the controller is controller.py): a ROS 2 context on
this process's domain, the simulator's node, its publishers of the loopback simulator's topics
and the messages it sends, and the ordered hand-over of one control period's inputs.

What it does: :class:`Bridge` publishes the route, goal and map (transient local), the
odometry, the scan (both reliable, so a node's default-QoS subscription matches as a sensor-data
one does), the transforms (``/tf`` each period, ``/tf_static`` once a run: tf.py) and the
clock. :meth:`Bridge.hand_over` gives the node each of a period's inputs only
once every reliable reader of the one before has acknowledged it, and the clock last: so a
node's callbacks see a period's messages in one order, whatever the machine's load, and a node
that acts on a timer on simulated time finds the period's scan and odometry in when the clock
moves to fire it.

Why: a node that acts on whatever arrived last (the usual way) computes from the previous
period's odometry when DDS happens to deliver the scan first, and its runs then differ from one
try to the next (docs/ros2.md, "Determinism").

Parameters: :data:`ACK_TIMEOUT_S` (wall seconds a reader has to acknowledge a message).

Source: Nav2's loopback simulator (topics, frames, QoS), REP 105 (frames), the DDS
reliability protocol's acknowledgements (``Publisher.wait_for_all_acked``).
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import time
from collections.abc import Callable, Collection, Mapping
from typing import Any

import numpy as np

from sitgen.controllers.deadlines import ControllerError
from sitgen.controllers.proc_tasks import wait_idle
from sitgen.controllers.ros2.dds_domain import confine, process_domain, rmw_problem
from sitgen.controllers.ros2.messages import (
    FRAMES,
    TOPICS,
    answer_of,
    control_period_s,
    float32s,
    laser_scan,
    occupancy_data,
    quaternion,
    scan_constants,
    sec_nanosec,
    stamp,
)
from sitgen.controllers.ros2.native import native_period
from sitgen.controllers.ros2.tf import tf_message_type

ACK_TIMEOUT_S = 1.0
"""Wall seconds a node's reliable readers have to acknowledge one message of a period before
the next is handed over anyway (a node that stops reading is then caught by the answer's
timeout)."""
LIB = os.path.join(sys.prefix, "lib")
"""Where the ROS 2 wheels put their shared libraries (the rmw implementations among them)."""


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
    from geometry_msgs.msg import (
        PoseStamped,
        PoseWithCovarianceStamped,
        TransformStamped,
        Twist,
        TwistStamped,
    )
    from nav_msgs.msg import OccupancyGrid, Odometry, Path
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import LaserScan

    return {
        "PoseStamped": PoseStamped,
        "PoseWithCovarianceStamped": PoseWithCovarianceStamped,
        "Twist": Twist,
        "TwistStamped": TwistStamped,
        "TransformStamped": TransformStamped,
        "Odometry": Odometry,
        "Path": Path,
        "OccupancyGrid": OccupancyGrid,
        "Clock": Clock,
        "LaserScan": LaserScan,
        "Time": Time,
    }


class Bridge:
    """sitgen's side of one run: a ROS 2 context on this process's domain, the simulator's
    node with its publishers, and an executor. A fresh one per node started (a node kept
    alive keeps its bridge): a participant that has seen a node die keeps its locators for
    seconds, and a new node on the same ports would wait that long to be discovered."""

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
        )

        self.msg = _messages()
        # sitgen's own participant is held to this machine as the node is: a test run must
        # not announce itself to, or hear from, the network (rcl reads these at init).
        confine(os.environ)
        self.domain = process_domain()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        # A simulator's node has no parameters to serve, and nothing to log to /rosout: fewer
        # services for every turn of the executor to look at.
        self.node = rclpy.create_node(
            "sitgen_sim",
            context=self.context,
            start_parameter_services=False,
            enable_rosout=False,
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self._waits: Any = None
        self._scan: tuple[Mapping[str, Any], Any] | None = None
        self.executor.add_node(self.node)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        reliable = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        m = self.msg
        self.clock = self.node.create_publisher(m["Clock"], TOPICS.clock, reliable)
        # Reliable, kept as sensor data keeps it: a node's sensor-data (best-effort)
        # subscription matches it, and so does one with the default QoS, which a best-effort
        # publisher would leave without a scan.
        sensor = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        self.scan = self.node.create_publisher(m["LaserScan"], TOPICS.scan, sensor)
        self.odom = self.node.create_publisher(m["Odometry"], TOPICS.odom, reliable)
        self.plan = self.node.create_publisher(m["Path"], TOPICS.plan, latched)
        self.goal = self.node.create_publisher(m["PoseStamped"], TOPICS.goal, latched)
        self.map = self.node.create_publisher(m["OccupancyGrid"], TOPICS.map, latched)
        # As RViz's "2D Pose Estimate" publishes it (and Nav2's loopback simulator reads it).
        self.initialpose = self.node.create_publisher(
            m["PoseWithCovarianceStamped"], TOPICS.initialpose, reliable
        )
        # As a robot's driver and robot_state_publisher publish them (tf2's listener reads
        # /tf_static transient local); None, with the reason kept, where tf2_msgs cannot be had.
        self.tf: Any = None
        self.tf_static: Any = None
        self.tf_problem: str | None = None
        self.tf_read = False
        """Whether the node reads /tf (from the graph once it is discovered): each message
        handed over is waited on, so /tf is sent only where it is read."""
        try:
            self.msg["TFMessage"] = tf_message_type()
            self.tf = self.node.create_publisher(m["TFMessage"], TOPICS.tf, reliable)
            self.tf_static = self.node.create_publisher(m["TFMessage"], TOPICS.tf_static, latched)
        except ControllerError as e:
            self.tf_problem = str(e)
        except Exception as e:  # a tf2_msgs whose type support is broken: /tf only is lost
            self.tf, self.tf_static = None, None
            self.tf_problem = f"ros2: tf2_msgs's type support does not work: {e}"
        self.native = native_period()
        """The period's hand-over in C (None: in Python, native.py)."""
        self._pointers: Any = None
        """The rcl handles of the odometry's, scan's and clock's publishers, for the C side."""

    def published(self) -> list[Any]:
        """sitgen's publishers of a run's inputs."""
        publishers = [self.clock, self.scan, self.odom, self.plan, self.goal, self.initialpose]
        return publishers + [p for p in (self.tf, self.tf_static) if p is not None]

    def hand_over(
        self,
        messages: list[tuple[Any, Any]],
        settle: Callable[[], object] | None = None,
        taken: bool = False,
    ) -> None:
        """Publish each (publisher, message) in turn, each only once every reliable reader of
        the one before has acknowledged it (it is in the reader's queue) and ``settle`` has
        returned (the node has gone back to waiting, its callback for it run), so that the
        node's callbacks see a period's messages in this order however loaded the machine
        is. The first waits on ``settle`` too: the node may still be at the previous period's
        clock. ``taken``: the last one too is waited for so before returning."""
        from rclpy.duration import Duration

        for k, (publisher, message) in enumerate(messages):
            if k > 0:
                messages[k - 1][0].wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
                # Not before the clock: a node's executor takes the clock before its other
                # messages of the same turn (the time source subscribes first), and a timer
                # it makes ready fires only on the executor's next turn.
                if settle is not None and publisher is not self.clock:
                    settle()
            publisher.publish(message)
        if taken and messages:
            messages[-1][0].wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
            if settle is not None:
                settle()

    def period(
        self, info: Mapping[str, Any], obs: Mapping[str, Any], t: float
    ) -> list[tuple[Any, Any]]:
        """The messages of the control period that starts at simulated time ``t``, in the
        order a node gets them: the odometry, odom → base_link on /tf (where the node reads
        it) and the scan stamped ``t``, then the clock at the period's end, ``t`` plus the
        control period (so a timer on simulated time at the control rate fires once a period,
        the first included, with the period's scan, odometry and transform in)."""
        m = self.msg
        x, y, heading = (float(c) for c in obs["pose"])
        clock = m["Clock"]()
        clock.clock = stamp(m, t, control_period_s(info))
        messages = [(self.odom, self._odometry(t, x, y, heading, obs["velocity"]))]
        if self.tf is not None and self.tf_read:
            base = self.transform(t, FRAMES.odom, FRAMES.base, x, y, heading)
            messages.append((self.tf, m["TFMessage"](transforms=[base])))
        messages.append((self.scan, self._scan_at(info, obs["ranges"], t)))
        return [*messages, (self.clock, clock)]

    def hand_over_period(
        self,
        goal: list[tuple[Any, Any]],
        info: Mapping[str, Any],
        obs: Mapping[str, Any],
        t: float,
        pids: Collection[int],
        settle_s: float,
    ) -> None:
        """``hand_over(goal + period(info, obs, t), settle)``, where settling is waiting at
        most ``settle_s`` for the processes ``pids`` to go back to waiting: in C where it can
        be (no new goal this period, the node does not read /tf, and native.py has its
        hand-over), else in Python; the same messages, in the same order, either way."""
        if goal or self.native is None or (self.tf is not None and self.tf_read):
            self.hand_over(goal + self.period(info, obs, t), lambda: wait_idle(pids, settle_s))
            return
        period_s = control_period_s(info)
        frames = (FRAMES.odom, FRAMES.base, FRAMES.scan)
        self.native.setup(info, frames, lambda: scan_constants(info, period_s))
        pose, velocity = obs["pose"], obs["velocity"]
        _, _, qz, qw = quaternion(float(pose[2]))
        if self._pointers is None:
            self._pointers = tuple(p.handle.pointer for p in (self.odom, self.scan, self.clock))
        self.native.hand_over(
            self._pointers,
            sec_nanosec(t),
            sec_nanosec(t, period_s),
            (float(pose[0]), float(pose[1]), qz, qw, float(velocity[0]), float(velocity[1])),
            obs["ranges"],
            pids,
            settle_s,
            ACK_TIMEOUT_S,
        )

    def _odometry(self, t: float, x: float, y: float, heading: float, velocity: Any) -> Any:
        odom = self.msg["Odometry"]()
        odom.header.stamp, odom.header.frame_id = stamp(self.msg, t), FRAMES.odom
        odom.child_frame_id = FRAMES.base
        odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
        q = odom.pose.pose.orientation
        q.x, q.y, q.z, q.w = quaternion(heading)
        v, omega = (float(c) for c in velocity)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = v, omega
        return odom

    def _scan_at(self, info: Mapping[str, Any], ranges: Any, t: float) -> Any:
        """The period's scan: the run's first made whole, later ones its ranges and stamp
        changed (rclpy checks every field a message is built with, each period)."""
        if self._scan is None or self._scan[0] is not info:
            self._scan = (info, laser_scan(self.msg, info, ranges, t))
            return self._scan[1]
        scan = self._scan[1]
        scan.header.stamp = stamp(self.msg, t)
        scan.ranges = float32s(ranges)
        return scan

    def transform(
        self, t: float, parent: str, child: str, x: float, y: float, heading: float
    ) -> Any:
        """A geometry_msgs/TransformStamped at simulated time ``t``: ``child``'s frame in
        ``parent``'s, at (``x``, ``y``) turned by ``heading``."""
        message = self.msg["TransformStamped"]()
        message.header.stamp, message.header.frame_id = stamp(self.msg, t), parent
        message.child_frame_id = child
        message.transform.translation.x, message.transform.translation.y = x, y
        q = message.transform.rotation
        q.x, q.y, q.z, q.w = quaternion(heading)
        return message

    def static_transforms(self, info: Mapping[str, Any]) -> list[tuple[Any, Any]]:
        """/tf_static for a run: ``map`` → ``odom`` (they coincide: no localisation error
        is modelled) and ``base_link`` → ``base_scan`` (the laser's mount, ``offset_x_m``
        ahead); nothing where tf2_msgs cannot be had."""
        if self.tf_static is None:
            return []
        offset = float(info["laser"].get("offset_x_m", 0.0))
        transforms = [
            self.transform(0.0, FRAMES.map, FRAMES.odom, 0.0, 0.0, 0.0),
            self.transform(0.0, FRAMES.base, FRAMES.scan, offset, 0.0, 0.0),
        ]
        return [(self.tf_static, self.msg["TFMessage"](transforms=transforms))]

    def clock_at(self, t: float) -> Any:
        """A /clock message at simulated time ``t``."""
        clock = self.msg["Clock"]()
        clock.clock = stamp(self.msg, t)
        return clock

    def initial_pose(self, start: Any) -> Any:
        """The robot's start ``(x, y, heading)`` as an /initialpose message at time 0, frame
        ``map``, with a zero covariance (the pose is known exactly)."""
        message = self.msg["PoseWithCovarianceStamped"]()
        message.header.frame_id, message.header.stamp = FRAMES.map, stamp(self.msg, 0.0)
        pose = message.pose.pose
        pose.position.x, pose.position.y = float(start[0]), float(start[1])
        q = pose.orientation
        q.x, q.y, q.z, q.w = quaternion(float(start[2]))
        return message

    def call_resets(self, name: str, timeout_s: float, check_alive: Callable[[str], None]) -> None:
        """Call every reset service the node offers (:attr:`Topics.reset`), each matched and
        answered within ``timeout_s`` wall seconds; ControllerError, naming the controller
        ``name``, where one does not answer or a Trigger answers that it failed."""
        for service, kind in self.reset_services():
            request_type = _service_type(kind)
            client: Any = self.node.create_client(request_type, service)
            try:
                deadline = time.monotonic() + timeout_s
                late = ControllerError(
                    f"controller {name}: its reset service {service} did not answer within "
                    f"{timeout_s:g} s"
                )
                alive = functools.partial(check_alive, f"on its reset ({service})")
                # The service is in the graph; a request sent before the client has matched
                # it would be lost.
                self._spin_until(client.service_is_ready, deadline, late, alive)
                future = client.call_async(request_type.Request())
                self._spin_until(future.done, deadline, late, alive)
                response: Any = future.result()
                if kind.endswith("Trigger") and not response.success:
                    raise ControllerError(
                        f"controller {name}: its reset service {service} failed: "
                        f"{response.message!r}"
                    )
            finally:
                self.node.destroy_client(client)

    def _spin_until(
        self,
        done: Callable[[], bool],
        deadline: float,
        late: ControllerError,
        alive: Callable[[], None],
    ) -> None:
        """Spin until ``done``; ``late`` is raised past the wall-clock ``deadline``, and
        ``alive`` (which raises if the node has died) is called between."""
        while not done():
            alive()
            if time.monotonic() > deadline:
                raise late
            self.spin(0.01)

    def reset_services(self) -> list[tuple[str, str]]:
        """The node's reset services as (name, type), in name order."""
        me = self.node.get_name()
        found = []
        for service, kinds in self.node.get_service_names_and_types():
            if service != f"/{TOPICS.reset}" and not service.endswith(f"/{TOPICS.reset}"):
                continue
            if service.startswith(f"/{me}/"):
                continue
            found += [(service, k) for k in kinds if k in RESET_TYPES]
        return sorted(found)

    def map_message(self, grid: Mapping[str, Any]) -> Any:
        """The situation's map (reset info's ``map``) as nav_msgs/OccupancyGrid in frame
        ``map``, for /map (transient local, as a map server serves it)."""
        m = self.msg
        occupied = np.asarray(grid["occupied"], dtype=bool)
        message = m["OccupancyGrid"]()
        message.header.frame_id, message.header.stamp = FRAMES.map, stamp(m, 0.0)
        message.info.resolution = float(grid["resolution_m"])
        message.info.height, message.info.width = (int(n) for n in occupied.shape)
        message.info.origin.orientation.w = 1.0
        message.data = occupancy_data(occupied).tolist()
        return message

    def spin(self, timeout_s: float) -> None:
        self.executor.spin_once(timeout_sec=max(0.0, timeout_s))

    def take(self, subscription: Any, timeout_s: float) -> Any | None:
        """The next message of ``subscription``, waiting at most ``timeout_s`` wall seconds
        for one; None if none came. It waits on that subscription alone (as rclpy's
        ``wait_for_message`` does), not on everything the executor watches: a period's answer
        is read in a few microseconds rather than an executor's turn."""
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        deadline = time.monotonic() + timeout_s
        while True:
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
            if taken is not None:
                return taken[0]
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            if self._waits is None:
                context = self.context.handle
                assert context is not None  # the bridge's context is live until shutdown
                with context:
                    self._waits = _rclpy.WaitSet(1, 0, 0, 0, 0, 0, context)
            with subscription.handle:
                self._waits.clear_entities()
                self._waits.add_subscription(subscription.handle)
                self._waits.wait(int(left * 1e9))

    def take_answer(
        self, subscription: Any, stamped: bool, timeout_s: float
    ) -> tuple[float, float, float] | None:
        """The node's next answer on ``subscription`` (:func:`answer_of`), waiting at most
        ``timeout_s`` wall seconds for it: in C where the period's hand-over is (the same
        wait on that subscription alone), else :meth:`take`."""
        if self.native is not None:
            context = self.context.handle
            assert context is not None  # the bridge's context is live until shutdown
            return self.native.take_answer(
                subscription.handle.pointer, context.pointer, stamped, timeout_s
            )
        message = self.take(subscription, timeout_s)
        return None if message is None else answer_of(message, stamped)

    def all_matched(self, listening_will_do: bool = False) -> bool:
        """Whether the node listens to the scan or the odometry, and (unless
        ``listening_will_do``) every subscription to sitgen's topics that discovery has seen
        is matched by sitgen's publisher (so the first observation is not lost to a
        half-finished discovery)."""
        publishers = self.published()
        listening = self.scan.get_subscription_count() + self.odom.get_subscription_count()
        return listening > 0 and (
            listening_will_do
            or all(
                p.get_subscription_count() >= self._subscriptions_seen(p.topic_name)
                for p in publishers
            )
        )

    def tf_unserved(self) -> str | None:
        """Why the node's subscription to /tf or /tf_static goes unserved (sitgen has no
        tf2_msgs here); None where it has none or sitgen publishes them."""
        if self.tf_problem is None:
            return None
        topics = (TOPICS.tf, TOPICS.tf_static)
        listened = [t for t in topics if self._subscriptions_seen(t) > 0]
        if not listened:
            return None
        return f"it subscribes to {' and '.join(listened)}, but {self.tf_problem}"

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
                for p in self.published()
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
        if self.native is not None:
            self.native.release()
        with contextlib.suppress(Exception):
            self.executor.shutdown(timeout_sec=0)
            self.node.destroy_node()
            self.context.try_shutdown()


RESET_TYPES = ("std_srvs/srv/Trigger", "std_srvs/srv/Empty")
"""The types a node's reset service may have."""


def _service_type(kind: str) -> Any:
    # std_srvs is part of sitgen[ros2]; a node can only offer such a service where it exists.
    from std_srvs.srv import Empty, Trigger

    return Trigger if kind.endswith("Trigger") else Empty

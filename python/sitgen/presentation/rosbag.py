"""A run as a rosbag2 (MCAP storage), for ROS tools: Foxglove or Lichtblick, ``ros2 bag play``.

What it writes, on simulated time from 0 (frames as Nav2's loopback simulator names them, REP
105; docs/ros2.md):

- ``/map`` (nav_msgs/OccupancyGrid, transient-local, once) and ``/plan`` (nav_msgs/Path: the
  agent's route, once);
- every step: ``/clock``, ``/scan`` (the agent's laser, frame ``base_scan``), ``/odom`` (the
  agent, ``odom`` → ``base_link``), ``/tf`` (the agent's ``odom`` → ``base_link`` and every
  peer's ``map`` → ``peer_ID/base_link``), ``/peers/ID/odom`` (each peer), ``/cmd_vel``
  (geometry_msgs/TwistStamped: the velocity the agent moved with over the step, as the
  simulator applied its command);
- ``/tf_static`` (transient-local: ``map`` → ``odom``, which coincide, and ``base_link`` →
  ``base_scan``);
- ``/events`` (visualization_msgs/MarkerArray): each of the monitor's events at its start, a
  sphere and a label at the robot it concerns, red if it scored, grey if not, shown for as long
  as the event lasted (at least a second).

Why this way: the bag is written from a run as it happens (:func:`sitgen.run.run` with
``sensed=True``), so the scans are the ones the controller saw; message definitions are
embedded (rosbags' ROS 2 Kilted typestore, TFMessage among them even where no tf2_msgs is
installed), so any MCAP reader decodes it without ROS.

Source: rosbag2's MCAP storage and metadata (version 9), via the ``rosbags`` library.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from sitgen.controllers.ros2.messages import FRAMES, occupancy_data, quaternion, sec_nanosec
from sitgen.run import RunRecord, reset_info
from sitgen.store import Store, StoreError
from sitgen.triage.recall import resimulate_checked, stored_run
from sitgen.world.situation import Situation

# The frames a live ros2: run uses (REP 105, as Nav2's loopback simulator names them).
MAP, ODOM, BASE, SCAN = FRAMES.map, FRAMES.odom, FRAMES.base, FRAMES.scan
EVENT_MIN_S = 1.0
"""Shortest time an event's marker stays on screen, seconds."""

TOPICS = {
    "/map": "nav_msgs/msg/OccupancyGrid",
    "/plan": "nav_msgs/msg/Path",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/scan": "sensor_msgs/msg/LaserScan",
    "/odom": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/cmd_vel": "geometry_msgs/msg/TwistStamped",
    "/events": "visualization_msgs/msg/MarkerArray",
}
LATCHED = ("/map", "/tf_static", "/plan")


class RosbagUnavailable(Exception):
    """The rosbags library is not installed (it comes with sitgen[ros2])."""


def _typestore() -> Any:
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise RosbagUnavailable(
            "rosbag2 export needs the rosbags library: pip install 'sitgen[ros2]'"
        ) from None
    return get_typestore(Stores.ROS2_KILTED)


def peer_odom_topic(robot_id: int) -> str:
    return f"/peers/{robot_id}/odom"


def peer_frame(robot_id: int) -> str:
    return f"peer_{robot_id}/{BASE}"


class _Messages:
    """Messages of the Kilted typestore, built from blanks (every field at its zero) so that
    only the fields that carry something are named."""

    _NUMPY: ClassVar[dict[str, Any]] = {
        "bool": np.bool_,
        "byte": np.uint8,
        "char": np.uint8,
        "int8": np.int8,
        "uint8": np.uint8,
        "int16": np.int16,
        "uint16": np.uint16,
        "int32": np.int32,
        "uint32": np.uint32,
        "int64": np.int64,
        "uint64": np.uint64,
        "float32": np.float32,
        "float64": np.float64,
    }

    def __init__(self, store: Any) -> None:
        self.store = store

    def blank(self, msgtype: str, **fields: Any) -> Any:
        _, defs = self.store.fielddefs[msgtype]
        values = {name: self._blank_field(desc) for name, desc in defs}
        values.update(fields)
        return self.store.types[msgtype](**values)

    def _blank_field(self, desc: Any) -> Any:
        from rosbags.interfaces import Nodetype

        kind, detail = desc
        if kind == Nodetype.BASE:
            name = detail[0]
            if name in ("string", "wstring"):
                return ""
            return False if name == "bool" else self._NUMPY[name](0).item()
        if kind == Nodetype.NAME:
            return self.blank(detail)
        (sub_kind, sub_detail), length = detail
        if sub_kind == Nodetype.BASE and sub_detail[0] in self._NUMPY:
            return np.zeros(length if kind == Nodetype.ARRAY else 0, self._NUMPY[sub_detail[0]])
        return [self._blank_field((sub_kind, sub_detail)) for _ in range(length)]

    def stamp(self, t: float) -> Any:
        sec, nanosec = sec_nanosec(t)
        return self.blank("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)

    def header(self, t: float, frame: str) -> Any:
        return self.blank("std_msgs/msg/Header", stamp=self.stamp(t), frame_id=frame)

    def pose(self, x: float, y: float, heading: float) -> Any:
        _, _, z, w = quaternion(heading)
        q = self.blank("geometry_msgs/msg/Quaternion", z=z, w=w)
        point = self.blank("geometry_msgs/msg/Point", x=float(x), y=float(y))
        return self.blank("geometry_msgs/msg/Pose", position=point, orientation=q)

    def transform(self, t: float, parent: str, child: str, x: float, y: float, h: float) -> Any:
        pose = self.pose(x, y, h)
        translation = self.blank("geometry_msgs/msg/Vector3", x=float(x), y=float(y))
        return self.blank(
            "geometry_msgs/msg/TransformStamped",
            header=self.header(t, parent),
            child_frame_id=child,
            transform=self.blank(
                "geometry_msgs/msg/Transform", translation=translation, rotation=pose.orientation
            ),
        )

    def twist(self, v: float, omega: float) -> Any:
        return self.blank(
            "geometry_msgs/msg/Twist",
            linear=self.blank("geometry_msgs/msg/Vector3", x=float(v)),
            angular=self.blank("geometry_msgs/msg/Vector3", z=float(omega)),
        )

    def odometry(self, t: float, parent: str, child: str, pose: Any, v: float, w: float) -> Any:
        return self.blank(
            "nav_msgs/msg/Odometry",
            header=self.header(t, parent),
            child_frame_id=child,
            pose=self.blank("geometry_msgs/msg/PoseWithCovariance", pose=self.pose(*pose)),
            twist=self.blank("geometry_msgs/msg/TwistWithCovariance", twist=self.twist(v, w)),
        )


def body_velocities(poses: npt.NDArray[np.float64], dt_s: float) -> npt.NDArray[np.float64]:
    """(v, omega) of a robot over each step from its poses (rows x, y, heading): forward
    speed along its heading and turn rate, over the step ending at each row (zero at row 0)."""
    velocity = np.zeros((len(poses), 2))
    if len(poses) > 1:
        d = np.diff(poses, axis=0)
        heading = poses[:-1, 2]
        velocity[1:, 0] = (d[:, 0] * np.cos(heading) + d[:, 1] * np.sin(heading)) / dt_s
        velocity[1:, 1] = np.remainder(d[:, 2] + np.pi, 2 * np.pi) - np.pi
        velocity[1:, 1] /= dt_s
    return velocity


def write_rosbag2(
    folder: Path, situation: Situation, record: RunRecord, run_spec: Mapping[str, Any]
) -> Path:
    """Write run ``record`` of ``situation`` (run with ``sensed=True`` under ``run_spec``) as
    a rosbag2 folder ``folder`` (which must not exist yet); returns the MCAP file's path."""
    store = _typestore()
    if record.sensed is None:
        raise ValueError("the run was not kept with what the agent sensed (sensed=True)")
    with _claimed(folder) as draft:
        _write_bag(draft, store, situation, record, run_spec)
    return next(folder.glob("*.mcap"))


@contextlib.contextmanager
def _claimed(folder: Path) -> Iterator[Path]:
    """A bag is written whole or not at all, and never over anything: ``folder`` is claimed
    by creating it (so a second export into it at the same time is refused, not mixed in),
    the bag is written into a hidden folder beside it and moved into place once complete;
    on any failure (a full disk) both are removed. Yields where to write the bag (a folder
    named as ``folder``, so that its MCAP file is named after ``folder``)."""
    try:
        folder.mkdir()
    except FileExistsError:
        # Never written through, or over: a bag goes into a new folder.
        raise FileExistsError(
            f"{folder}: is there already (or another export is writing it); a rosbag2 is "
            "written to a new folder"
        ) from None
    try:
        scratch = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    except BaseException:
        folder.rmdir()
        raise
    try:
        yield scratch / folder.name
        # rename(2) puts a folder in place of an empty one: the claimed folder.
        os.rename(scratch / folder.name, folder)
    except BaseException:
        # The claimed folder is removed only while it is empty: what anyone else put in it
        # since stays.
        with contextlib.suppress(OSError):
            folder.rmdir()
        raise
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _write_bag(
    folder: Path,
    store: Any,
    situation: Situation,
    record: RunRecord,
    run_spec: Mapping[str, Any],
) -> None:
    """The bag itself, into ``folder`` (which does not exist yet)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    from rosbags.rosbag2 import StoragePlugin, Writer

    never = QosTime(sec=0, nsec=0)
    latched = Qos(
        QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
        never, never, QosLiveliness.AUTOMATIC, never, False,
    )  # fmt: skip
    m = _Messages(store)
    peers = [r.id for r in situation.robots[1:]]
    topics = dict(TOPICS) | {peer_odom_topic(p): "nav_msgs/msg/Odometry" for p in peers}
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            topic: writer.add_connection(
                topic,
                msgtype,
                typestore=store,
                offered_qos_profiles=[latched] if topic in LATCHED else [],
            )
            for topic, msgtype in topics.items()
        }
        for t, topic, message in _messages(m, situation, record, run_spec):
            writer.write(
                connections[topic],
                round(t * 1e9),
                store.serialize_cdr(message, topics[topic]),
            )


def _messages(
    m: _Messages, situation: Situation, record: RunRecord, run_spec: Mapping[str, Any]
) -> Iterator[tuple[float, str, Any]]:
    """(time, topic, message) in time order (the bag's log time)."""
    assert record.sensed is not None
    info = reset_info(situation, run_spec, situation.agent.id)
    dt_s = float(info["dt_s"])
    sensed = record.sensed
    trajectory = np.asarray(record.trajectory, dtype=np.float64)
    agent = situation.agent
    yield 0.0, "/map", _occupancy_grid(m, situation)
    yield 0.0, "/plan", _path(m, agent.waypoints)
    offset = float(info["laser"]["offset_x_m"])
    yield (
        0.0,
        "/tf_static",
        m.blank(
            "tf2_msgs/msg/TFMessage",
            transforms=[
                m.transform(0.0, MAP, ODOM, 0.0, 0.0, 0.0),
                m.transform(0.0, BASE, SCAN, offset, 0.0, 0.0),
            ],
        ),
    )
    peer_velocity = {
        p: body_velocities(trajectory[:, k, :], dt_s)
        for k, p in enumerate(r.id for r in situation.robots)
        if k > 0
    }
    markers = _event_markers(m, record.events, trajectory, situation, dt_s)
    laser = info["laser"]
    angles = laser["angles"]
    for i in range(len(trajectory)):
        t = float(sensed.time_s[i])
        yield t, "/clock", m.blank("rosgraph_msgs/msg/Clock", clock=m.stamp(t))
        for array in markers.get(i, []):
            yield t, "/events", array
        pose = trajectory[i, 0]
        v, omega = sensed.velocity[i]
        yield t, "/odom", m.odometry(t, ODOM, BASE, pose, v, omega)
        yield (
            t,
            "/scan",
            m.blank(
                "sensor_msgs/msg/LaserScan",
                header=m.header(t, SCAN),
                angle_min=float(angles[0]),
                angle_max=float(angles[-1]),
                angle_increment=(angles[-1] - angles[0]) / max(1, len(angles) - 1),
                scan_time=dt_s,
                range_max=float(laser["range_m"]),
                ranges=sensed.ranges[i].astype(np.float32),
            ),
        )
        transforms = [m.transform(t, ODOM, BASE, *pose)]
        for k, robot in enumerate(situation.robots[1:], start=1):
            transforms.append(m.transform(t, MAP, peer_frame(robot.id), *trajectory[i, k]))
            pv, pw = peer_velocity[robot.id][i]
            odom = m.odometry(t, MAP, peer_frame(robot.id), trajectory[i, k], pv, pw)
            yield t, peer_odom_topic(robot.id), odom
        yield t, "/tf", m.blank("tf2_msgs/msg/TFMessage", transforms=transforms)
        if i + 1 < len(trajectory):
            # The velocity it moved with over the coming step: its command, within the limits.
            cv, cw = sensed.velocity[i + 1]
            command = m.blank(
                "geometry_msgs/msg/TwistStamped", header=m.header(t, BASE), twist=m.twist(cv, cw)
            )
            yield t, "/cmd_vel", command


def _occupancy_grid(m: _Messages, situation: Situation) -> Any:
    grid = situation.grid
    rows, cols = grid.occupied.shape
    data = occupancy_data(grid.occupied)
    meta = m.blank(
        "nav_msgs/msg/MapMetaData",
        resolution=float(grid.resolution),
        width=cols,
        height=rows,
        origin=m.pose(0.0, 0.0, 0.0),
    )
    return m.blank("nav_msgs/msg/OccupancyGrid", header=m.header(0.0, MAP), info=meta, data=data)


def _path(m: _Messages, waypoints: Sequence[Sequence[float]]) -> Any:
    poses = [
        m.blank("geometry_msgs/msg/PoseStamped", header=m.header(0.0, MAP), pose=m.pose(x, y, 0))
        for x, y in waypoints
    ]
    return m.blank("nav_msgs/msg/Path", header=m.header(0.0, MAP), poses=poses)


def _event_markers(
    m: _Messages,
    events: Sequence[Mapping[str, Any]],
    trajectory: npt.NDArray[np.float64],
    situation: Situation,
    dt_s: float,
) -> dict[int, list[Any]]:
    """A MarkerArray for each event, by the step it starts at: a sphere and a label at the
    robot it concerns (marker ids are the event's position in the log)."""
    index = {r.id: k for k, r in enumerate(situation.robots)}
    out: dict[int, list[Any]] = {}
    for n, event in enumerate(events):
        t = float(event["start_s"])
        step = min(len(trajectory) - 1, round(t / dt_s))
        x, y, _ = trajectory[step, index.get(event["robot"], 0)]
        end = event.get("end_s")
        seconds = max(EVENT_MIN_S, (float(end) - t) if end is not None else 0.0)
        sec, nanosec = sec_nanosec(seconds)
        lifetime = m.blank("builtin_interfaces/msg/Duration", sec=sec, nanosec=nanosec)
        red = bool(event.get("scored"))
        colour = m.blank(
            "std_msgs/msg/ColorRGBA",
            r=0.9 if red else 0.5,
            g=0.1 if red else 0.5,
            b=0.1 if red else 0.5,
            a=0.8,
        )
        label = f"{event['kind']} (robot {event['robot']})"
        common = dict(header=m.header(t, MAP), id=n, lifetime=lifetime, color=colour)
        sphere = m.blank(
            "visualization_msgs/msg/Marker",
            ns=event["kind"],
            type=2,  # SPHERE
            pose=m.pose(x, y, 0.0),
            scale=m.blank("geometry_msgs/msg/Vector3", x=0.8, y=0.8, z=0.8),
            text=label,
            **common,
        )
        text = m.blank(
            "visualization_msgs/msg/Marker",
            ns=f"{event['kind']}/label",
            type=9,  # TEXT_VIEW_FACING
            pose=m.pose(x, y + 0.8, 0.0),
            scale=m.blank("geometry_msgs/msg/Vector3", z=0.5),
            text=label,
            **common,
        )
        array = m.blank("visualization_msgs/msg/MarkerArray", markers=[sphere, text])
        out.setdefault(step, []).append(array)
    return out


def write_stored_run(store: Store, run_id: int, folder: Path) -> Path:
    """Stored run ``run_id`` as a rosbag2 in ``folder``: run again (keeping what the agent
    sensed) and checked to be the run that was stored (:func:`resimulate_checked`), so that
    the bag's poses and events are the stored run's and its scans are what the controller saw.
    Raises StoreError (no such run, or it does not re-run the same)."""
    row = stored_run(store, run_id)
    if row["content_hash"] is None:
        raise StoreError(f"{store.path}: run {run_id} has no situation (generation failed)")
    situation, record = resimulate_checked(store, row, sensed=True)
    return write_rosbag2(folder, situation, record, row["run_spec"])


def is_report_bag(path: Path) -> bool:
    """Whether ``path`` is a bag folder as a report writes one (a folder, not a link, holding
    only its ``metadata.yaml`` and MCAP files): the one thing a report may remove."""
    if path.is_symlink() or not path.is_dir():
        return False
    return all(
        f.is_file() and not f.is_symlink() and (f.name == "metadata.yaml" or f.suffix == ".mcap")
        for f in path.iterdir()
    )

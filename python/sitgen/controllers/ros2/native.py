"""A control period's hand-over in C (``period.c``), for bridge.py: the odometry,
scan and clock published through rclpy's own publishers, in the order and with the waits of
:meth:`Bridge.hand_over <sitgen.controllers.ros2.bridge.Bridge.hand_over>`, and the node's
answer taken from rclpy's own /cmd_vel subscription as :meth:`Bridge.take
<sitgen.controllers.ros2.bridge.Bridge.take>` takes it.

What it does: :func:`native_period` builds ``period.c`` once per environment with the
machine's gcc against the ROS 2 wheels (native_build.py), loads it, and returns a
:class:`NativePeriod`; None where it cannot be had (no gcc, a failed build) or is turned off
(``SITGEN_ROS2_NATIVE=0``), and the bridge then hands every period over in Python, with the same
messages in the same order (tests/test_ros2.py compares runs made both ways).

Why: in Python, sitgen's side of a period (three messages built and converted by rclpy, the
node's thread states read from /proc between them, the answer taken and converted) took about
1 ms; in C, sitgen's own part is tens of microseconds beside DDS's round trips (timed once in an
instrumented copy; make bench times the whole period both ways; docs/ros2.md,
"Cost").

Parameters: ``SITGEN_ROS2_NATIVE`` (environment; default ``1``; ``0`` hands every period over
in Python, to compare the two or to rule the C side out when a run surprises).

Source: rcl's C API; ctypes.
"""

from __future__ import annotations

import ctypes
import functools
import os
import threading
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sitgen.controllers.deadlines import ControllerError
from sitgen.controllers.ros2.native_build import (
    build_key,
    build_once,
    cache_dir,
    check_call,
    compile_flags,
    link_flags,
    missing_compilers,
)

SOURCE = Path(__file__).with_name("period.c")
LIBRARY = "libsitgen_ros2_period.so"
WHAT = "the native period hand-over"
WHEELS = (
    "ros-rcl",
    "ros-geometry-msgs",
    "ros-nav-msgs",
    "ros-sensor-msgs",
    "ros-rosgraph-msgs",
    "ros-rosidl-runtime-c",
)
"""The wheels whose headers and structures the build depends on."""
LIBRARIES = (
    "rcl",
    "rcutils",
    "rosidl_runtime_c",
    "geometry_msgs__rosidl_generator_c",
    "nav_msgs__rosidl_generator_c",
    "sensor_msgs__rosidl_generator_c",
    "rosgraph_msgs__rosidl_generator_c",
)
_LOCK = threading.Lock()
"""The library keeps one set of messages and one wait set: one caller at a time (ctypes lets
go of the GIL during a call)."""
_c_float = ctypes.c_float
_c_double = ctypes.c_double


class NativePeriod:
    """The loaded hand-over: :meth:`setup` once a run, :meth:`hand_over` each period."""

    def __init__(self, library: ctypes.CDLL) -> None:
        self._lib = library
        library.sitgen_period_problem.restype = ctypes.c_char_p
        library.sitgen_period_setup.restype = ctypes.c_int
        library.sitgen_period_setup.argtypes = [ctypes.c_char_p] * 3 + [_c_float] * 7
        library.sitgen_period_hand_over.restype = ctypes.c_int
        library.sitgen_period_hand_over.argtypes = [
            *[ctypes.c_void_p] * 3,
            ctypes.c_int32,
            ctypes.c_uint32,
            ctypes.c_int32,
            ctypes.c_uint32,
            *[_c_double] * 6,
            ctypes.c_void_p,
            ctypes.c_size_t,
            ctypes.c_void_p,
            ctypes.c_size_t,
            _c_double,
            _c_double,
        ]
        library.sitgen_answer_take.restype = ctypes.c_int
        library.sitgen_answer_take.argtypes = [
            ctypes.c_void_p,
            ctypes.c_void_p,
            ctypes.c_int,
            ctypes.c_int64,
            ctypes.c_void_p,
        ]
        library.sitgen_answer_release.restype = None
        self._answer = (_c_double * 3)()
        self._set_up_for: object = None
        self._pids: tuple[int, ...] = ()
        self._pid_array: Any = (ctypes.c_int * 0)()

    def setup(
        self, run: object, frames: Sequence[str], scan: Callable[[], Sequence[float]]
    ) -> None:
        """The messages' frame ids (odometry, base, scan) and the scan's constant fields
        (``scan()``: angle_min, angle_max, angle_increment, time_increment, scan_time,
        range_min, range_max), as the Python path sets them, for ``run`` (any object that is
        the same for all of a run's periods): set again only when ``run`` changes (whichever
        bridge of the process asks; the library holds one set of messages)."""
        with _LOCK:
            if run is self._set_up_for:
                return
            if self._lib.sitgen_period_setup(*(f.encode() for f in frames), *scan()) != 0:
                raise ControllerError(f"ros2: {self._problem()}")
            self._set_up_for = run

    def hand_over(
        self,
        publishers: tuple[int, int, int],
        stamp: tuple[int, int],
        clock: tuple[int, int],
        odometry: tuple[float, float, float, float, float, float],
        ranges: Any,
        pids: Collection[int],
        settle_s: float,
        ack_timeout_s: float,
    ) -> None:
        """Publish the period's odometry (x, y, the orientation's z and w, v, ω, stamped
        ``stamp``), scan (``ranges``) and clock (``clock``) through the rcl publishers at
        ``publishers``, each after the one before is acknowledged (within ``ack_timeout_s``)
        and the scan once the processes ``pids`` have gone back to waiting (within
        ``settle_s``)."""
        values = np.ascontiguousarray(ranges, dtype=np.float32)
        with _LOCK:
            if len(pids) != len(self._pids) or any(pid not in pids for pid in self._pids):
                self._pids = tuple(sorted(pids))
                self._pid_array = (ctypes.c_int * len(self._pids))(*self._pids)
            done = self._lib.sitgen_period_hand_over(
                *publishers,
                *stamp,
                *clock,
                *odometry,
                values.ctypes.data,
                values.size,
                ctypes.addressof(self._pid_array),
                len(self._pids),
                settle_s,
                ack_timeout_s,
            )
            if done != 0:
                raise ControllerError(f"ros2: {self._problem()}")

    def take_answer(
        self, subscription: int, context: int, stamped: bool, timeout_s: float
    ) -> tuple[float, float, float] | None:
        """The next answer on the rcl subscription at ``subscription`` (a Twist, or a
        TwistStamped where ``stamped``) as (v, ω, its stamp in seconds; 0 unstamped), waiting
        at most ``timeout_s`` wall seconds on it alone (a wait set of the rcl context at
        ``context``); None if none came."""
        timeout_ns = max(0, int(timeout_s * 1e9))
        with _LOCK:
            got = self._lib.sitgen_answer_take(
                subscription, context, int(stamped), timeout_ns, self._answer
            )
            if got < 0:
                raise ControllerError(f"ros2: {self._problem()}")
            return (self._answer[0], self._answer[1], self._answer[2]) if got else None

    def release(self) -> None:
        """Give back the answer's wait set (before its context is shut down)."""
        with _LOCK:
            self._lib.sitgen_answer_release()

    def _problem(self) -> str:
        problem: bytes = self._lib.sitgen_period_problem()
        return problem.decode(errors="replace")


def native_period() -> NativePeriod | None:
    """The hand-over in C, built and loaded on first use; None where it cannot be had
    (:func:`native_problem` says why)."""
    return _native()[0]


def native_problem() -> str | None:
    """Why periods are handed over in Python (None: they are not)."""
    return _native()[1]


@functools.cache
def _native() -> tuple[NativePeriod | None, str | None]:
    if os.environ.get("SITGEN_ROS2_NATIVE", "1") == "0":
        return None, "SITGEN_ROS2_NATIVE=0"
    try:
        folder = build_once(_folder(), LIBRARY, _build)
        return NativePeriod(ctypes.CDLL(str(folder / LIBRARY))), None
    except (ControllerError, OSError) as e:
        return None, str(e)


def _folder() -> Path:
    return cache_dir() / f"ros2-period-{build_key(WHEELS, SOURCE.read_text())}"


def _build(work: Path) -> Path:
    """``period.c`` compiled and linked under ``work``; the folder to keep."""
    missing = missing_compilers("gcc")
    if missing:
        raise ControllerError(f"ros2: {WHAT} is built with gcc, which is not on PATH")
    out = work / "staged"
    out.mkdir()
    command = ["gcc", "-O2", "-fPIC", "-shared", str(SOURCE), "-o", str(out / LIBRARY)]
    command += [*compile_flags(), *link_flags(LIBRARIES)]
    check_call(command, dict(os.environ), WHAT, "compile")
    return out

"""A run that calls user code in this process, made in a child forked for it: the fast path's
isolation.

What it does: :func:`forked` calls a function in a child process forked from this one and
returns what it returned (pickled through a pipe), or :class:`Died` when the child ended without
an answer. The child leads a process group of its own, is killed if this process dies
(PR_SET_PDEATHSIG), and carries a controller mark (:data:`sitgen.controllers.external.MARK`)
under this process's, so that sitgen's reaper finds what it started should sitgen be killed
outright. When the child ends — returning, raising, calling ``os._exit``, crashing, killed by
the step watchdog — every process it started is killed: this process is a child subreaper
(PR_SET_CHILD_SUBREAPER), so every orphan of the run, a double-forked daemon included, comes
back to it as its child. What the run left in the process — threads, non-daemon ones too,
signal handlers, a SIGALRM sender, imported modules — ends with the child. A user's fork
that returns into sitgen's code (a class that forks without exec) ends there at once
(:func:`returned_in_fork`), and a ``killpg(0, …)`` reaches the run's group, never sitgen.

While the child calls a controller it writes who and when into a page shared with this process
(:func:`note`), so that a child that dies is reported as the host process reports a controller
that dies: which controller, at what simulated time, and whether the step watchdog killed it.

Why: a ``python:`` class called in a campaign's pool worker (:mod:`sitgen.controllers.inprocess`)
runs at the core's speed but shared the worker with everything it did; a host process
(:mod:`sitgen.controllers.host`) isolates it at the cost of a pipe round trip a step. A fork a
run costs about a millisecond and none a step.

Parameters: :data:`NAME_BYTES` (bytes, 240) the longest controller name a report keeps; up to
:data:`SLOTS` (16) controllers a run.

Source: Linux's prctl(2) (PR_SET_CHILD_SUBREAPER, PR_SET_PDEATHSIG), pidfd_open(2), proc(5)'s
``/proc/PID/task/TID/children``.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import mmap
import os
import pickle
import select
import signal
import struct
import sys
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

from sitgen import _core
from sitgen.controllers.external import MARK, marked_env, signal_name

T = TypeVar("T")

SLOTS = 16
NAME_BYTES = 240
_HEADER = 64
"""The shared page: four doubles (slot, phase, simulated time, timeout) then SLOTS names."""

IN_RESET, AT_STEP, IN_CLOSE = 0.0, 1.0, 2.0
"""Phases of a controller call, as :func:`note` records them."""

_PR_SET_PDEATHSIG = 1
_PR_SET_CHILD_SUBREAPER = 36
_LIBC: Any = None


@dataclass(frozen=True)
class Died:
    """The child ended without an answer: how, and the call it was in (as noted)."""

    how: str
    """``was killed by SIGSEGV``, ``exited with code 7``, …"""
    watchdog: bool
    """The step watchdog killed it: a call ran past its timeout and ignored SIGALRM."""
    name: str
    """The controller it was calling (its shown name), or "" if none was noted."""
    when: str
    """``in reset``, ``at 12.3 s``, ``in close``."""
    timeout_s: float
    """The timeout of that call."""

    def reason(self) -> str:
        """The run's one-line reason, worded as the host process's."""
        who = f"controller {self.name}" if self.name else "the run's process"
        if self.watchdog:
            return f"{who} did not reply within {self.timeout_s:g} s {self.when}"
        return f"{who} {self.how} {self.when}".rstrip()


class _Shared:
    """The child's side of the shared page (None outside a forked run)."""

    view: Any = None
    names: ClassVar[dict[str, int]] = {}
    owner = 0
    """The forked run's own pid: a process that finds another is a user's fork of it."""


def note(name: str, phase: float, time_s: float, timeout_s: float) -> None:
    """Record that the child is calling controller ``name`` (a no-op outside a forked run)."""
    view = _Shared.view
    if view is None:
        return
    slot = _Shared.names.get(name)
    if slot is None:
        slot = min(len(_Shared.names), SLOTS - 1)
        _Shared.names[name] = slot
        raw = name.encode()[: NAME_BYTES - 1]
        start = _HEADER + slot * NAME_BYTES
        view.obj[start : start + NAME_BYTES] = raw.ljust(NAME_BYTES, b"\0")
    view[0], view[1], view[2], view[3] = float(slot), phase, time_s, timeout_s


def note_time(time_s: float) -> None:
    """Record the simulated time of the step being asked for (the controller as last noted)."""
    view = _Shared.view
    if view is not None:
        view[2] = time_s


def returned_in_fork() -> None:
    """End this process at once if it is a user's fork of a forked run that returned into
    sitgen's code (a class that forks without exec): only the run's own process goes on."""
    if _Shared.view is not None and os.getpid() != _Shared.owner:
        os._exit(0)


def _libc() -> Any:
    global _LIBC
    if _LIBC is None:
        _LIBC = ctypes.CDLL(None, use_errno=True)
    return _LIBC


def _become_subreaper() -> None:
    """Orphans of this process's descendants become its children (Linux), so a run's daemons
    are found and killed when the run ends."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            _libc().prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)


def _children() -> set[int]:
    """This process's live children, from every thread's children list (a thread forks them;
    a subreaper's orphans join its threads)."""
    found: set[int] = set()
    with contextlib.suppress(OSError):
        for tid in os.listdir("/proc/self/task"):
            with contextlib.suppress(OSError), open(f"/proc/self/task/{tid}/children") as f:
                found.update(int(p) for p in f.read().split())
    return found


def _kill_new_children(before: set[int]) -> None:
    """SIGKILL and reap every child this process has that it did not have ``before``, again
    and again while killing them orphans more (their own children come back here)."""
    for _ in range(100):
        new = _children() - before
        if not new:
            return
        for pid in new:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        for pid in new:
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(pid, 0)


def forked(work: Callable[[], T]) -> T | Died:
    """``work()`` called in a child forked for it: its result, or how the child died. A
    BaseException that ``work`` raises is raised here again (pickled), so that sitgen's own
    errors read as before; a user's code is expected to be guarded inside ``work``."""
    _become_subreaper()
    page = mmap.mmap(-1, _HEADER + SLOTS * NAME_BYTES)
    view = memoryview(page).cast("d")
    view[0] = -1.0
    read_end, write_end = os.pipe()
    report_read, report_write = os.pipe()
    for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
        with contextlib.suppress(Exception):
            stream.flush()
    parent = os.getpid()
    # The parent's mark (its reaper started once per process, here and not in every child).
    mark = os.environ.get(MARK) or marked_env()[1]
    before = _children()
    # What the parent has allocated stays out of the child's collections: a collection that
    # walked it would copy most of the parent's pages into the child (copy-on-write).
    gc.freeze()
    pid = os.fork()
    if pid != 0:
        gc.unfreeze()
    if pid == 0:  # the child: never returns
        os.close(read_end)
        os.close(report_read)
        _child(work, parent, mark, view, write_end, report_write)
    os.close(write_end)
    os.close(report_write)
    try:
        payload, status = _wait(pid, read_end)
    except BaseException:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError, OSError):
            os.waitpid(pid, 0)
        raise
    finally:
        os.close(read_end)
        _kill_new_children(before)
    try:
        watchdog = _readable(report_read) and os.read(report_read, 1) == b"W"
    finally:
        os.close(report_read)
    died = None if payload is not None else _died(status, watchdog, view, page)
    view.release()
    page.close()
    if died is not None:
        return died
    assert payload is not None
    kind, value = pickle.loads(payload)
    if kind == "raised":
        raise value
    result: T = value
    return result


def _child(
    work: Callable[[], Any], parent: int, mark: str, view: Any, write_end: int, report_write: int
) -> None:
    code = 0
    try:
        os.setpgid(0, 0)
        with contextlib.suppress(OSError, AttributeError):
            _libc().prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        # A parent that died before the line above is not watched for: gone already.
        if os.getppid() != parent:
            os._exit(70)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _Shared.view, _Shared.names, _Shared.owner = view, {}, os.getpid()
        os.environ[MARK] = f"{mark}.{uuid.uuid4().hex}"
        _core.watchdog_report(report_write)
        try:
            message = ("ok", work())
        except BaseException as e:  # sitgen's own error, raised again in the parent
            message = ("raised", e)
        returned_in_fork()
        try:
            payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as e:
            payload = pickle.dumps(("raised", RuntimeError(f"unpicklable result: {e}")))
        _write_all(write_end, struct.pack("<Q", len(payload)) + payload)
    except BaseException:
        code = 70
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(BaseException):
                stream.flush()
        os._exit(code)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def _readable(fd: int) -> bool:
    return bool(select.select([fd], [], [], 0)[0])


def _wait(pid: int, read_end: int) -> tuple[bytes | None, int]:
    """The child's answer (None if it gave none) and its wait status. The answer is read as it
    comes (a large one would fill the pipe); the end is the child's exit, never the pipe's, which
    a user's fork may hold open."""
    length: int | None = None
    data = bytearray()
    pidfd = _pidfd(pid)
    poller = select.poll()
    poller.register(read_end, select.POLLIN)
    if pidfd is not None:
        poller.register(pidfd, select.POLLIN)
    try:
        while True:
            ready = {fd for fd, _ in poller.poll(None if pidfd is not None else 50)}
            if read_end in ready:
                chunk = os.read(read_end, 1 << 20)
                if not chunk:
                    poller.unregister(read_end)
                data += chunk
                if length is None and len(data) >= 8:
                    length = struct.unpack("<Q", data[:8])[0]
                if length is not None and len(data) >= 8 + length:
                    break
            if pidfd is None or pidfd in ready:
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    # Whatever it wrote before it ended is in the pipe now.
                    while _readable(read_end):
                        chunk = os.read(read_end, 1 << 20)
                        if not chunk:
                            break
                        data += chunk
                    if len(data) >= 8:
                        length = struct.unpack("<Q", data[:8])[0]
                    if length is not None and len(data) >= 8 + length:
                        return bytes(data[8 : 8 + length]), status
                    return None, status
        _, status = os.waitpid(pid, 0)
        assert length is not None
        return bytes(data[8 : 8 + length]), status
    finally:
        if pidfd is not None:
            os.close(pidfd)


def _pidfd(pid: int) -> int | None:
    try:
        return os.pidfd_open(pid)
    except (OSError, AttributeError):
        return None


def _died(status: int, watchdog: bool, view: Any, page: mmap.mmap) -> Died:
    if os.WIFSIGNALED(status):
        how = f"was killed by {signal_name(os.WTERMSIG(status))}"
    else:
        how = f"exited with code {os.waitstatus_to_exitcode(status)}"
    slot = int(view[0])
    if slot < 0:
        return Died(how, False, "", "", 0.0)
    phase, time_s, timeout_s = view[1], view[2], view[3]
    start = _HEADER + slot * NAME_BYTES
    name = bytes(page[start : start + NAME_BYTES]).split(b"\0", 1)[0].decode(errors="replace")
    when = {IN_RESET: "in reset", IN_CLOSE: "in close"}.get(phase, f"at {time_s:.1f} s")
    return Died(how, watchdog, name, when, timeout_s)

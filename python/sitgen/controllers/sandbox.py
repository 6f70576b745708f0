"""Runs that call user code in this process, made in a child forked for them: the fast path's
isolation.

What it does: :func:`call` hands a function and its arguments to this thread's *runner*, a child
process forked from this one, and returns what it returned (pickled through pipes), or
:class:`Died` when the runner ended without an answer. The runner leads a process group of its
own, is killed if the thread that forked it ends (PR_SET_PDEATHSIG), carries a controller mark
(:data:`sitgen.controllers.marks.MARK`) under this process's, so that sitgen's reaper finds
what it started should sitgen be killed outright, and is a child subreaper: every orphan of a
run, a double-forked daemon included, comes back to it, and when a run ends every process the
run started is killed. The runner then looks at itself: a run that left a thread, a signal
handler, an interval timer, a blocked signal, a file descriptor, another working folder,
process group or environment is *dirty*, and the runner answers and exits, so that the next
run gets a fresh one forked from this process; a clean run leaves it for the next. A user's fork
that returns into sitgen's code (a class that forks without exec) ends there at once
(:func:`returned_in_fork`), and a ``killpg(0, …)`` reaches the runner's group, never sitgen.

While the runner calls a controller it writes who and when into a page shared with this process
(:func:`note`), so that a runner that dies is reported as the host process reports a controller
that dies: which controller, at what simulated time, and whether the step watchdog killed it.

Why: a ``python:`` class called in a campaign's pool worker (:mod:`sitgen.controllers.inprocess`)
runs at the core's speed but shared the worker with everything it did; a host process
(:mod:`sitgen.controllers.host`) isolates it at the cost of a pipe round trip a step. A fork for
each run cost 10-17 ms a run (fork, exit, copy-on-write); a runner kept while clean costs a
message each way a run, and a fork only after a run that changed its process.

Parameters: :data:`NAME_BYTES` (bytes, 240) the longest controller name a report keeps; up to
:data:`SLOTS` (16) controllers a run.

Source: Linux's prctl(2) (PR_SET_CHILD_SUBREAPER, PR_SET_PDEATHSIG), pidfd_open(2), proc(5)'s
``/proc/PID/task/TID/children``, ``/proc/self/task`` and ``/proc/self/fd``.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import gc
import mmap
import os
import pickle
import select
import signal
import struct
import sys
import threading
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

from sitgen import _core
from sitgen.controllers.deadlines import backstop_s, computing_too_long
from sitgen.controllers.external import signal_name
from sitgen.controllers.marks import MARK, marked_env

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
    watchdog: str
    """Why the step watchdog killed it: ``cpu`` (a call used up its processor time and ignored
    SIGPROF), ``wall`` (it ran past its backstop and ignored SIGALRM); "" it did not."""
    name: str
    """The controller it was calling (its shown name), or "" if none was noted."""
    when: str
    """``in reset``, ``at 12.3 s``, ``in close``."""
    timeout_s: float
    """The timeout of that call."""

    def reason(self) -> str:
        """The run's one-line reason, worded as the host process's."""
        who = f"controller {self.name}" if self.name else "the run's process"
        if self.watchdog == "cpu":
            return computing_too_long(self.name, self.timeout_s, self.when)
        if self.watchdog:
            return f"{who} did not reply within {backstop_s(self.timeout_s):g} s {self.when}"
        return f"{who} {self.how} {self.when}".rstrip()


class _Shared:
    """The child's side of the shared page (None outside a forked run)."""

    view: Any = None
    names: ClassVar[dict[str, int]] = {}


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


def page() -> Any:
    """The shared page as doubles, for a caller that records each step's simulated time in
    its third (index 2) itself; None outside a runner."""
    return _Shared.view


FORKED = [False]
"""Whether this process is a fork of a runner (set in every child ``os.fork`` makes, cleared
by the runner itself): read each step, where a call of getpid would cost more."""


def _forked() -> None:
    FORKED[0] = True


os.register_at_fork(after_in_child=_forked)


def returned_in_fork() -> None:
    """End this process at once if it is a user's fork of a runner that returned into
    sitgen's code (a class that forks without exec): only the runner goes on."""
    if FORKED[0] and _Shared.view is not None:
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


def _kill_children_but(spared: set[int]) -> None:
    """SIGKILL and reap every child of this process but ``spared``, again and again while
    killing them orphans more (their own children come back to a subreaper)."""
    for _ in range(100):
        doomed = _children() - spared
        if not doomed:
            return
        for pid in doomed:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        for pid in doomed:
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(pid, 0)


class _Runner:
    """This side of a runner: its pid and the pipes and page shared with it."""

    def __init__(self) -> None:
        _become_subreaper()
        # The parent's mark (its reaper started once per process, here and not in the runner).
        mark = os.environ.get(MARK) or marked_env()[1]
        self.page = mmap.mmap(-1, _HEADER + SLOTS * NAME_BYTES)
        self.view = memoryview(self.page).cast("d")
        self.view[0] = -1.0
        request_read, self.requests = os.pipe()
        self.replies, reply_write = os.pipe()
        # A run's record (its trajectory) is hundreds of kilobytes: in one pipe's worth, not in
        # sixteen turns of a 64 KB one between two processes that may share one core.
        with contextlib.suppress(OSError, AttributeError):
            fcntl.fcntl(reply_write, fcntl.F_SETPIPE_SZ, 1 << 20)
        self.reports, report_write = os.pipe()
        for stream in (sys.stdout, sys.stderr):  # nothing buffered is written twice
            with contextlib.suppress(Exception):
                stream.flush()
        parent = os.getpid()
        # What the parent has allocated stays out of the runner's collections: a collection
        # that walked it would copy most of the parent's pages into the runner (copy-on-write).
        gc.freeze()
        try:
            pid = os.fork()
        except BaseException:
            gc.unfreeze()
            raise
        if pid == 0:  # the runner: never returns
            for fd in (self.requests, self.replies, self.reports):
                os.close(fd)
            _serve(parent, mark, self.view, request_read, reply_write, report_write)
        gc.unfreeze()
        for fd in (request_read, reply_write, report_write):
            os.close(fd)
        self.pid = pid
        self.pidfd = _pidfd(pid)
        self.before: set[int] = set()
        """This process's children when the runner was last asked: not the runner's orphans."""
        with _RUNNERS_LOCK:
            _RUNNER_PIDS.add(pid)

    def alive(self) -> bool:
        if self.pidfd is not None:
            return not _readable(self.pidfd)
        return os.waitpid(self.pid, os.WNOHANG)[0] == 0

    def ask(self, request: bytes) -> tuple[bytes | None, int | None]:
        """Send ``request`` and wait: the answer and None, or None and the wait status of a
        runner that ended without one (it is reaped)."""
        self.before = _children()
        try:
            _write_all(self.requests, struct.pack("<Q", len(request)) + request)
        except OSError:  # it ended before it read the request
            return None, self.reap()
        data = bytearray()
        poller = select.poll()
        poller.register(self.replies, select.POLLIN)
        if self.pidfd is not None:
            poller.register(self.pidfd, select.POLLIN)
        while True:
            ready = {fd for fd, _ in poller.poll(None if self.pidfd is not None else 50)}
            if self.replies in ready:
                chunk = os.read(self.replies, 1 << 20)
                if not chunk:
                    poller.unregister(self.replies)
                data += chunk
                answer = _framed(data)
                if answer is not None:
                    return answer, None
            if (self.pidfd is None or self.pidfd in ready) and not self.alive():
                # Whatever it wrote before it ended is in the pipe now.
                while _readable(self.replies):
                    chunk = os.read(self.replies, 1 << 20)
                    if not chunk:
                        break
                    data += chunk
                answer = _framed(data)
                if answer is not None:
                    return answer, None
                return None, self.reap()

    def reap(self) -> int:
        """Wait for the runner to end (it is ending or has ended), kill whatever it left (its
        orphans are this process's children now) and give its pipes back: its wait status."""
        try:
            status = os.waitpid(self.pid, 0)[1]
        except ChildProcessError:
            status = 0
        with _RUNNERS_LOCK:
            _RUNNER_PIDS.discard(self.pid)
            spared = self.before | _RUNNER_PIDS
        _kill_children_but(spared)
        for fd in (self.requests, self.replies):
            with contextlib.suppress(OSError):
                os.close(fd)
        if self.pidfd is not None:
            os.close(self.pidfd)
        return status

    def died(self, status: int) -> Died:
        said = os.read(self.reports, 1) if _readable(self.reports) else b""
        watchdog = {b"W": "wall", b"C": "cpu"}.get(said, "")
        died = _died(status, watchdog, self.view, self.page)
        self.close_page()
        return died

    def close_page(self) -> None:
        os.close(self.reports)
        self.view.release()
        self.page.close()


_LOCAL = threading.local()
"""This thread's runner (PR_SET_PDEATHSIG ties a runner to the thread that forked it)."""
_RUNNERS_LOCK = threading.Lock()
_RUNNER_PIDS: set[int] = set()
"""Every live runner of this process, which killing a runner's leftovers spares."""


def call(work: Callable[..., T], *args: Any) -> T | Died:
    """``work(*args)`` made by this thread's runner (``work`` a module-level function, it and
    ``args`` picklable): its result, or how the runner died. A BaseException that ``work``
    raises is raised here again, so that sitgen's own errors read as before; a user's code is
    expected to be guarded inside ``work``."""
    request = pickle.dumps((work, args), protocol=pickle.HIGHEST_PROTOCOL)
    for _ in range(2):  # a runner that ended between runs is replaced once
        runner = _runner()
        answer, status = runner.ask(request)
        if answer is not None:
            break
        assert status is not None
        _LOCAL.runner = None
        died = runner.died(status)
        if died.name:
            return died
        # It ended outside any controller's call: between runs (killed while idle), or in
        # sitgen's own code of this run; a fresh runner makes the run once more.
        last = died
    else:
        return last
    (kind, value), clean = pickle.loads(answer)
    if not clean:  # it exits after answering: the next run gets a fresh one
        _LOCAL.runner = None
        runner.reap()
        runner.close_page()
    if kind == "raised":
        raise value
    result: T = value
    return result


def _runner() -> _Runner:
    runner: _Runner | None = getattr(_LOCAL, "runner", None)
    if runner is not None and getattr(_LOCAL, "pid", None) == os.getpid() and runner.alive():
        return runner
    if runner is not None and getattr(_LOCAL, "pid", None) == os.getpid():
        runner.reap()  # it ended while idle (killed from outside): its status is no run's
        runner.close_page()
    made = _Runner()
    _LOCAL.runner, _LOCAL.pid = made, os.getpid()
    return made


def inside() -> bool:
    """Whether this process is a runner."""
    return _Shared.view is not None


def _serve(
    parent: int, mark: str, view: Any, requests: int, replies: int, report_write: int
) -> None:
    """The runner: make each request's run and answer, until this process is dirty or the
    parent closes its end."""
    code = 0
    try:
        os.setpgid(0, 0)
        with contextlib.suppress(OSError, AttributeError):
            _libc().prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        # A parent that died before the line above is not watched for: gone already.
        if os.getppid() != parent:
            os._exit(70)
        _become_subreaper()
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _Shared.view, _Shared.names = view, {}
        FORKED[0] = False  # the runner itself: only a fork of it is a user's
        os.environ[MARK] = f"{mark}.{uuid.uuid4().hex}"
        _core.watchdog_report(report_write)
        _core.start_threads()
        state = _state()
        while True:
            request = _read_framed(requests)
            if request is None:
                break
            view[0] = -1.0
            _Shared.names = {}
            try:
                work, args = pickle.loads(request)
                message: tuple[str, Any] = ("ok", work(*args))
            except BaseException as e:  # sitgen's own error, raised again in the parent
                message = ("raised", e)
            returned_in_fork()
            view[0] = -1.0  # between runs: a death now is no controller's
            _kill_children_but(set())
            clean = _state() == state
            try:
                payload = pickle.dumps((message, clean), protocol=pickle.HIGHEST_PROTOCOL)
            except Exception as e:
                unpicklable = ("raised", RuntimeError(f"unpicklable result: {e}"))
                payload = pickle.dumps((unpicklable, False))
                clean = False
            _write_all(replies, struct.pack("<Q", len(payload)) + payload)
            if not clean:
                break
    except BaseException:
        code = 70
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(BaseException):
                stream.flush()
        os._exit(code)


def _state() -> tuple[Any, ...]:
    """What a run must leave as it found it for the runner to make the next: its threads,
    signal dispositions, blocked signals, interval timers, file descriptors, working folder,
    process group and environment."""
    dispositions = []
    for number in range(1, signal.NSIG):
        try:
            dispositions.append(signal.getsignal(number))
        except (OSError, ValueError):
            continue
    return (
        len(os.listdir("/proc/self/task")),
        dispositions,
        signal.pthread_sigmask(signal.SIG_BLOCK, []),
        signal.getitimer(signal.ITIMER_REAL),
        signal.getitimer(signal.ITIMER_PROF),
        sorted(os.listdir("/proc/self/fd")),
        os.getcwd(),
        os.getpgid(0),
        dict(os.environ),
    )


def _framed(data: bytearray) -> bytes | None:
    if len(data) < 8:
        return None
    length = struct.unpack("<Q", data[:8])[0]
    return bytes(data[8 : 8 + length]) if len(data) >= 8 + length else None


def _read_framed(fd: int) -> bytes | None:
    """One framed message from ``fd``; None at its end."""
    data = bytearray()
    while True:
        answer = _framed(data)
        if answer is not None:
            return answer
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            return None
        data += chunk


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def _readable(fd: int) -> bool:
    return bool(select.select([fd], [], [], 0)[0])


def _pidfd(pid: int) -> int | None:
    try:
        return os.pidfd_open(pid)
    except (OSError, AttributeError):
        return None


def _died(status: int, watchdog: str, view: Any, page: mmap.mmap) -> Died:
    if os.WIFSIGNALED(status):
        how = f"was killed by {signal_name(os.WTERMSIG(status))}"
    else:
        how = f"exited with code {os.waitstatus_to_exitcode(status)}"
    slot = int(view[0])
    if slot < 0:
        return Died(how, "", "", "", 0.0)
    phase, time_s, timeout_s = view[1], view[2], view[3]
    start = _HEADER + slot * NAME_BYTES
    name = bytes(page[start : start + NAME_BYTES]).split(b"\0", 1)[0].decode(errors="replace")
    when = {IN_RESET: "in reset", IN_CLOSE: "in close"}.get(phase, f"at {time_s:.1f} s")
    return Died(how, watchdog, name, when, timeout_s)

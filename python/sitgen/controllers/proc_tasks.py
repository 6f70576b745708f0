"""The states of a node's threads, as Linux's /proc shows them: whether a ``ros2:`` node has
gone back to waiting after a message, and whether its process has exited.

What it does: :func:`wait_idle` waits until every thread of some processes is asleep (none
running, runnable or waiting on a device), within a bound, Fast DDS's own threads left out
(:func:`protocol_thread`), and :func:`protocol_busy` whether those of a process still have work
in hand; :func:`task_state` reads one process's or thread's state letter;
:func:`cpu_seconds` the processor time some processes have used, :func:`schedstat_seconds`
how long their threads ran and waited for a core.

Why: a node's executor takes messages that arrived together in the order it made its
subscriptions, not the order they were sent; handing it a message only once it has gone back to
waiting keeps the order sitgen sends in (ros2/bridge.py, docs/ros2.md "Timing and
determinism"). The threads' stat files are kept open and read again from the start: a wait
looks at every thread of a node (a ROS 2 node has about twenty) many times a control period,
and opening each file anew cost about 25 µs a thread.

Parameters: none (the bound is the caller's).

Source: proc(5) (``/proc/PID/task/TID/stat``, its third field; ``/proc/PID/stat``, its 14th and
15th, ``utime`` and ``stime`` in clock ticks).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator


def task_state(stat_path: str) -> bytes | None:
    """The state letter in a process's or thread's /proc stat file (Linux: R running, S
    sleeping, D waiting on a device, Z exited and not yet reaped, …), or None where it is
    gone."""
    try:
        with open(stat_path, "rb") as f:
            stat = f.read()
    except OSError:
        return None
    return state_letter(stat)


STOPPED = (b"T", b"t")
"""The state letters of a process stopped by a signal (SIGSTOP, SIGTSTP) or by a debugger."""


def after_command(stat: bytes) -> bytes:
    """A /proc stat file's text from its third field (the state) on: after the command name,
    which may hold anything, spaces and parentheses included."""
    return stat[stat.rindex(b")") + 2 :]


def state_letter(stat: bytes) -> bytes:
    """The state letter of a /proc stat file's text."""
    return after_command(stat)[:1]


def cpu_seconds(pids: Iterable[int]) -> float:
    """The processor time, user and system, that the processes ``pids`` have used so far
    (every thread's, those that exited included); a process gone counts nothing."""
    ticks = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat", "rb") as f:
                stat = f.read()
        except OSError:
            continue
        fields = after_command(stat).split()  # fields[0] is the third, the state
        ticks += int(fields[11]) + int(fields[12])
    return ticks / os.sysconf("SC_CLK_TCK")


BUSY_SHARE = 0.25
"""Share of a core a controller that does not answer must use to be called busy (computing,
not waiting for input): one waiting uses next to none, and one that loops gets a whole core
on an idle machine but may get a third of one, or less, beside a busy machine's other work."""


def schedstat_seconds(pids: Iterable[int]) -> tuple[float, float]:
    """The time the live threads of the processes ``pids`` have spent running, and runnable
    but waiting on a run queue for a core (Linux's schedstat); zeros where the kernel keeps
    none."""
    running_ns = queued_ns = 0
    for pid, tid in threads(pids):
        try:
            with open(f"/proc/{pid}/task/{tid}/schedstat", "rb") as f:
                running, queued = f.read().split()[:2]
        except (OSError, ValueError):
            continue
        running_ns += int(running)
        queued_ns += int(queued)
    return running_ns / 1e9, queued_ns / 1e9


def threads(pids: Iterable[int]) -> Iterator[tuple[int, str]]:
    """(pid, thread id) of every live thread of the processes ``pids`` (a process gone has
    none)."""
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            yield pid, tid


PROTOCOL_THREADS = b"dds."
"""How Fast DDS names its own threads (``dds.ev.N`` its events and heartbeats, ``dds.udp.PORT``
its receivers, …)."""


def protocol_thread(stat: bytes) -> bool:
    """Whether a /proc stat file's thread is one of Fast DDS's own: it runs the DDS protocol
    (heartbeats, acknowledgements, receiving), never a node's callbacks, and by the time a
    reader's acknowledgement of a message reaches sitgen it has already woken the thread that
    will run the message's callback (Fast DDS notifies the reader's listener before it
    acknowledges), which is the one a wait is for."""
    return stat[stat.index(b"(") + 1 :].startswith(PROTOCOL_THREADS)


def protocol_busy(pid: int) -> bool:
    """Whether a Fast DDS thread of process ``pid`` is running or runnable (or waiting on a
    device): a message it received may still be on its way to a reader."""
    for _, tid in threads([pid]):
        try:
            with open(f"/proc/{pid}/task/{tid}/stat", "rb") as f:
                stat = f.read()
        except OSError:
            continue
        if protocol_thread(stat) and state_letter(stat) in (b"R", b"D"):
            return True
    return False


def wait_idle(pids: Iterable[int], timeout_s: float) -> bool:
    """Wait until every thread of the processes ``pids`` is asleep (blocked, waiting for
    input: Linux's /proc task states), within ``timeout_s`` of wall time; whether they were.
    A thread that is running or runnable has work in hand: a message it was woken for. Fast
    DDS's own threads are not waited for (:func:`protocol_thread`)."""
    deadline = time.monotonic() + timeout_s
    watched = _TASK_STATS.watch(pids)
    while True:
        if not any(state in (b"R", b"D") for state in _TASK_STATS.states(watched)):
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0)


class _TaskStats:
    """The /proc stat files of the threads of the processes a run waits on, kept open and
    read again from the start (``pread``)."""

    def __init__(self) -> None:
        self._files: dict[tuple[int, str], int] = {}

    def watch(self, pids: Iterable[int]) -> list[int]:
        """``pids`` as a list; the files of any other process are closed (a run waits on
        one node's processes at a time)."""
        pids = list(pids)
        for key in [k for k in self._files if k[0] not in pids]:
            os.close(self._files.pop(key))
        return pids

    def states(self, pids: list[int]) -> Iterator[bytes]:
        """The state letter of every thread of ``pids`` but Fast DDS's own (threads started
        since are found, and those gone dropped, on each call)."""
        for pid, tid in threads(pids):
            state = self._state(pid, tid)
            if state is not None:
                yield state

    def _state(self, pid: int, tid: str) -> bytes | None:
        key = (pid, tid)
        fd = self._files.get(key)
        if fd is None:
            try:
                fd = os.open(f"/proc/{pid}/task/{tid}/stat", os.O_RDONLY | os.O_CLOEXEC)
            except OSError:
                return None
            self._files[key] = fd
        try:
            stat = os.pread(fd, 4096, 0)
        except OSError:
            stat = b""
        if not stat:  # the thread has exited
            os.close(self._files.pop(key))
            return None
        return None if protocol_thread(stat) else state_letter(stat)


_TASK_STATS = _TaskStats()

"""How long a ``ros2:`` node's answer to a control period is waited for: its
``answer_timeout_s`` of processor time, with a wall-clock backstop.

What it does: :func:`answered_in_time` waits ``answer_timeout_s`` of wall time (a node on an
idle machine answers well within it); past that, it waits on only while the node is still at
work on the period — a thread of it running or runnable, or a Fast DDS thread of sitgen's
still delivering a message — and has used less than ``answer_timeout_s`` of processor time
since the period began, up to the backstop (:func:`~sitgen.controllers.deadlines.backstop_s`:
ten answer timeouts, at most 20 s more, at least 2 s). A node that has gone back to waiting
with nothing on its way has not answered, nor has one that used its time (its last command is
held for the period, as a late answer's always was); one that the machine kept from a core
until the backstop failed for the machine's reason (:class:`MachineError`: the run is made
again, never stored as the node's failure).

Why: wall time measures the machine. With the answer timeout counted in wall time, a loaded
machine changed which periods a node answered, and so the run: the example follower with
``answer_timeout_s = 0.02`` beside sixteen busy loops drove another trajectory than alone.
Counted as the node's own work, a period is answered or missed as it would be alone, as a
program's or a class's step deadline is (docs/controller-protocol.md, "Deadlines").

Parameters: the node's ``answer_timeout_s`` (wall seconds before its processor time is looked
at, and seconds of processor time; default the step timeout, 1 s).

Source: Linux's /proc (a process's processor time, its threads' states and schedstat;
proc(5)); :mod:`sitgen.controllers.proc_tasks`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Collection

from sitgen.controllers.deadlines import backstop_s, starved, starved_reason
from sitgen.controllers.external import CPU_COUNTED_AFTER_S, CPU_LOOK_S
from sitgen.controllers.proc_tasks import (
    cpu_seconds,
    protocol_busy,
    schedstat_seconds,
    wait_idle,
)


def answered_in_time(
    wait: Callable[[float], bool], pids: Collection[int], name: str, t: float, timeout_s: float
) -> bool:
    """Whether node ``name`` (processes ``pids``) answered the period at ``t`` in its time,
    ``wait(seconds)`` waiting that long at most for its answer (True once it is in). Raises
    MachineError where the machine starved it to the backstop."""
    start = time.monotonic()
    # Its processor time is read only for an answer not in after a short wait (most come
    # sooner, and the read costs more than a quick answer); what it used before is at most
    # that wait, which the deadline then grants it over.
    early = min(CPU_COUNTED_AFTER_S, timeout_s / 10)
    if wait(early):
        return True
    cpu_start = cpu_seconds(pids)
    if wait(max(0.0, start + timeout_s - time.monotonic())):
        return True
    backstop = start + backstop_s(timeout_s)
    window: tuple[float, float, float] | None = None
    while True:
        if cpu_seconds(pids) - cpu_start >= timeout_s:
            return False  # it computed for its whole time
        if wait_idle(pids, 0.0) and not protocol_busy(os.getpid()):
            # Gone back to waiting, and nothing it sent is still on its way: a last look takes
            # an answer delivered since the previous one.
            return wait(0.0)
        now = time.monotonic()
        if window is None:
            window = (now, *schedstat_seconds(pids))
        elif now >= backstop:
            running, queued = schedstat_seconds(pids)
            elapsed, used, waited = now - window[0], running - window[1], queued - window[2]
            if starved(elapsed, used, waited):
                raise starved_reason(name, backstop_s(timeout_s), f"at {t:.1f} s")
            return False
        if wait(min(CPU_LOOK_S, max(0.0, backstop - now))):
            return True

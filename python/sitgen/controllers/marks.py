"""Marks on the processes a controller starts, so that whatever a run started ends with it.

What it does: every controller process sitgen starts carries :data:`MARK` in its environment
(:func:`marked_env`), which everything it starts inherits; :func:`kill_marked` kills every live
process with a mark when its run ends, and each sitgen process's reaper (a small process of its
own) kills those of its marks once sitgen is gone, however it ended. :func:`die_with_parent_prefix`
makes a program die with the process that started it.

Why: a process group is not enough — a program may ``setsid``, double-fork a daemon or outlive
a parent that exits; the environment follows all of them (a process that clears its own
environment escapes, docs/limits.md).

Parameters: none.

Source: proc(5) (``/proc/PID/environ``); pidfd_open(2); setpriv(1) from util-linux.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import uuid
from collections.abc import Mapping
from typing import Any

MARK = "SITGEN_CONTROLLER_MARK"
"""The environment variable each controller process sitgen starts carries, as
``PROCESS.CONTROLLER``: every process it starts inherits it, even one that leaves its process
group (``setsid``) or whose parent exits, so :func:`kill_marked` finds them all when the run
ends, and this process's reaper (:func:`_reaper`) finds them when this process dies, however
it dies (even SIGKILL, which no handler sees)."""

_PROCESS: dict[str, Any] = {}
"""This process's part of the mark (``pid``, ``mark``) and its reaper, made the first time a
controller starts here (again in a forked child, whose pid differs)."""


def marked_env(env: Mapping[str, str] | None = None) -> tuple[dict[str, str], str]:
    """``env`` (default: this process's) with a fresh :data:`MARK`, and the mark; starts this
    process's reaper the first time."""
    if _PROCESS.get("pid") != os.getpid():
        mark = f"{os.getpid()}-{uuid.uuid4().hex}"
        _PROCESS.update(pid=os.getpid(), mark=mark, reaper=_reaper(mark))
    mark = f"{_PROCESS['mark']}.{uuid.uuid4().hex}"
    return {**(os.environ if env is None else env), MARK: mark}, mark


def _reaper(process_mark: str) -> subprocess.Popen[bytes]:
    """A small process that waits until this one is gone (a pidfd of it; where there is none,
    its stdin, a pipe this process holds, reaching end of file) and then kills every process a
    controller of this one started: what a run's own end would have killed, had it come."""
    env = {k: v for k, v in os.environ.items() if k != MARK}
    # It watches this process itself (a pidfd), not only its pipe: a fork of a controller's
    # (a double-forked daemon) holds the pipe open and would keep the reaper waiting.
    code = (
        "import os, select, sys\n"
        "try:\n"
        f"    select.select([os.pidfd_open({os.getpid()})], [], [])\n"
        "except ProcessLookupError:\n"
        "    pass\n"
        "except (OSError, AttributeError):\n"
        "    sys.stdin.buffer.read()\n"
        "from sitgen.controllers.marks import kill_marked\n"
        f"kill_marked({process_mark + '.'!r}, whole=False)\n"
    )
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=env,
    )


def marked_pids(mark: str, whole: bool = True) -> set[int]:
    """Every live process that carries ``mark`` (:func:`marked_env`; ``whole=False``: every
    mark that starts with it), other than this one. Linux's /proc; a process whose
    environment cannot be read (another user's) is not one sitgen started."""
    needle = f"\0{MARK}={mark}".encode() + (b"\0" if whole else b"")
    found = set()
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry.name}/environ", "rb") as f:
                if needle in b"\0" + f.read() + b"\0":
                    found.add(int(entry.name))
        except OSError:
            continue
    return found


def kill_marked(mark: str, whole: bool = True) -> int:
    """SIGKILL every process that carries ``mark`` (:func:`marked_pids`): whatever a
    controller started, wherever it went. Returns how many were killed."""
    killed = 0
    for pid in marked_pids(mark, whole):
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
            killed += 1
    return killed


def die_with_parent_prefix() -> list[str]:
    """``setpriv --pdeathsig KILL --`` where util-linux has it: the program is killed if the
    process that started it dies, even by SIGKILL (setpriv execs the program in its place)."""
    setpriv = shutil.which("setpriv")
    return [setpriv, "--pdeathsig", "KILL", "--"] if setpriv else []

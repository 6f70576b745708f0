"""Controllers written as a careless or unlucky user writes them: each does what ordinary Python
code does — starts a thread or a child, forks, cleans up its process group, raises from a
``__float__`` — at 0.3 s of a run (``FailsAt``), and must end, hang or kill nothing but its own
run. ``PIDS``: a file where one that starts processes writes their ids, if set."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any

from tests.controllers.pycontrollers import FailsAt, Forward


def _record(*pids: int) -> None:
    path = os.environ.get("SITGEN_TEST_PIDS")
    if path:
        with open(path, "a") as f:
            f.write("".join(f"{p}\n" for p in pids))


class Exiting:
    """A number whose conversion calls ``sys.exit``."""

    def __float__(self) -> float:
        sys.exit(3)


class Interrupting:
    """A number whose conversion raises KeyboardInterrupt."""

    def __float__(self) -> float:
        raise KeyboardInterrupt


class Unprintable(Exception):
    """An exception whose text cannot be had: its ``__str__`` exits."""

    def __str__(self) -> str:
        sys.exit(4)


class ExitsInFloat(Forward):
    def act(self, obs: Any) -> Any:
        return (Exiting(), 0.0) if obs.time > 0.25 else (0.3, 0.0)


class InterruptsInFloat(Forward):
    def act(self, obs: Any) -> Any:
        return (Interrupting(), 0.0) if obs.time > 0.25 else (0.3, 0.0)


class RaisesUnprintable(FailsAt):
    def fail(self) -> None:
        raise Unprintable


class ReturnsDigits(Forward):
    def act(self, obs: Any) -> Any:
        return "12"


class ReturnsBytes(Forward):
    def act(self, obs: Any) -> Any:
        return b"12"


class SwallowsTheTimeout(FailsAt):
    """Computes past its deadline inside ``except BaseException``, then answers."""

    def fail(self) -> None:
        end = time.process_time() + 1.5
        while time.process_time() < end:
            try:  # noqa: SIM105 - written as a careless user writes it
                sum(range(10_000))
            except BaseException:
                pass


class ExitsInClose(Forward):
    def close(self) -> None:
        sys.exit(2)


class SlowClose(Forward):
    def close(self) -> None:
        time.sleep(60)


class StartsAChild(Forward):
    """Starts a program at reset and never stops it."""

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        child = subprocess.Popen(["sleep", "600"])
        _record(child.pid)


class DoubleForks(Forward):
    """Starts a daemon the classic way (fork, setsid, fork) that keeps every inherited file
    open and lives on."""

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        first = os.fork()
        if first == 0:
            os.setsid()
            daemon = os.fork()
            if daemon == 0:
                time.sleep(600)
                os._exit(0)
            _record(daemon)  # before reset returns, so that the run's end cannot forestall it
            os._exit(0)
        os.waitpid(first, 0)


class StartsAThread(Forward):
    """Starts a non-daemon thread that never ends."""

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        threading.Thread(target=lambda: time.sleep(3600), daemon=False).start()


class KillsItsGroup(FailsAt):
    def fail(self) -> None:
        os.killpg(0, signal.SIGTERM)


class ForksWithoutExec(FailsAt):
    """Forks, and both processes return into whoever called it."""

    def fail(self) -> None:
        os.fork()


class SendsAlarms(Forward):
    """Leaves a daemon thread that sends SIGALRM to its process every 20 ms, and a SIGUSR1
    handler."""

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        signal.signal(signal.SIGUSR1, lambda *_: None)

        def pester() -> None:
            while True:
                time.sleep(0.02)
                os.kill(os.getpid(), signal.SIGALRM)

        threading.Thread(target=pester, daemon=True).start()


class RecordsItsProcess(Forward):
    """Writes its process id, its SIGUSR1 handler and its thread count at reset."""

    def reset(self, info: dict[str, Any]) -> None:
        super().reset(info)
        path = os.environ["SITGEN_TEST_PIDS"]
        handler = signal.getsignal(signal.SIGUSR1)
        with open(path, "a") as f:
            f.write(f"{os.getpid()} {handler == signal.SIG_DFL} {threading.active_count()}\n")


class DoubleForksSlowly(DoubleForks):
    """Starts its daemon, then takes 50 ms a step: a run lasts long enough to be killed."""

    def act(self, obs: Any) -> tuple[float, float]:
        time.sleep(0.05)
        return 0.3, 0.0


class Costs3ms(Forward):
    """Spends 3 ms of processor time a step, as a real planner does."""

    def act(self, obs: Any) -> tuple[float, float]:
        end = time.thread_time() + 0.003
        while time.thread_time() < end:
            pass
        return 0.3, 0.0

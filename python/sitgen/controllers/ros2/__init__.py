"""ROS 2 controllers (``ros2:PROGRAM``), everything they need in one package: the controller
(:mod:`.controller`), sitgen's side of a run over DDS (:mod:`.bridge`, :mod:`.messages`, its C
hand-over :mod:`.native` and ``period.c``), /tf's message type (:mod:`.tf`), what is built
against the ROS 2 wheels (:mod:`.native_build`) and the DDS domain a process claims
(:mod:`.dds_domain`). What ``cmd:`` programs share with nodes (reading a process's threads,
:mod:`sitgen.controllers.proc_tasks`; marking and killing what a controller starts,
:mod:`sitgen.controllers.external`) stays beside them, and imports nothing from here."""

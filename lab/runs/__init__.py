"""Runs: one experiment each, set up, run and scored. What the ``lab`` command calls.

* :mod:`lab.runs.robots`: :func:`make_robot`, the one switch from simulator to robot (a
  :class:`~lab.sim.SimRobot`, a rehearsal on the device emulators, or the real
  :class:`~lab.hardware.HardwareRobot` from a TOML file).
* :mod:`lab.runs.identify`: one identification episode (``lab identify``), on any of the three.
* :mod:`lab.runs.search`: one search trial in the lab room (``lab search``), with its navigator.
* :mod:`lab.runs.placement`: where a searchable object may stand (floor, table, shelf), by seed.
* :mod:`lab.runs.demo`: the identification demo and its report (``lab demo``).
* :mod:`lab.runs.rehearsal`: the hardware adapter on the emulators, the camera rendered by the simulator.

A run loads what the agents need from :mod:`lab.training`, hands it to them, and scores the result
against the simulator's truth (never shown to an agent). Figures come from :mod:`lab.viz`.
"""

"""Flights in virtual time: the mock drone in-process behind a simulated link.

:mod:`gcs.sim.loop` runs asyncio on a virtual clock; :mod:`gcs.sim.drone` is the mock drone
(:mod:`gcs.mock.vehicle`) reached by ``sim://NAME`` through a
:class:`gcs.flight.backend.VehicleLink`. Together they fly ``gcs fly``, ``gcs identify`` and
the campaign in the time their computations take (the tests' flights; docs/testing.md).
"""

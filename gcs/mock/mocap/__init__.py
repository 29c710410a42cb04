"""The mock motion-capture system: OptiTrack Motive's NatNet stream of one rigid body.

:mod:`gcs.mock.mocap.natnet` builds the packets (pure), :mod:`gcs.mock.mocap.server` serves
them in real time with marker noise and faults, ``python -m gcs.mock.mocap`` runs it as a
program. Protocol and tests: docs/mocap.md.
"""

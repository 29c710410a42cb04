"""Motion capture in the flight layer.

- :mod:`~gcs.core.frames`: from a system's axes to local NED (pure);
- :mod:`~gcs.flight.mocap.health`: is the stream usable right now (pure, one-line reasons);
- :mod:`~gcs.flight.mocap.checks`: pre-flight agreement of mocap and the vehicle (pure);
- :mod:`~gcs.io.mocap_source` (in the io layer: a URL is input): which system, where,
  which rigid body (``--mocap URL``);
- :mod:`~gcs.flight.mocap.client`: reads one rigid body through the ``motioncapture``
  library, in a reader process, delivering time-stamped samples to a thread.

Importing this package imports none of them (the library is loaded only by the reader).
"""

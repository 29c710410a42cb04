"""Exceptions of gcs.

Every error a user can cause derives from a builtin (``ValueError`` for bad input,
``RuntimeError`` for a vehicle that misbehaves) and from :class:`GcsError`, which the CLI
turns into one line on stderr and a non-zero exit code.
"""


class GcsError(Exception):
    """Base class of the errors the CLI reports as one line."""


class ProfileError(GcsError, ValueError):
    """A profile (YAML) is malformed or inconsistent; the message names file and field."""


class TrajectoryError(GcsError, ValueError):
    """A trajectory is malformed or beyond the vehicle's limits or the arena."""


class RunLogError(GcsError, ValueError):
    """A run directory or trial log is missing, truncated, NaN-filled or inconsistent."""


class ModelError(GcsError, ValueError):
    """A model cannot be used for learning (unstable, wrong shape, direct feedthrough)."""


class IdentificationError(GcsError, ValueError):
    """Identification data are insufficient (too short, not exciting, NaN)."""


class VehicleError(GcsError, RuntimeError):
    """The vehicle is unreachable, refused a command, or the link was lost."""


class TrialAborted(GcsError, RuntimeError):
    """A trial stopped before its end (watchdog, Ctrl-C, link loss); it is marked incomplete."""


class TrialPaused(TrialAborted):
    """A trial's stream fell behind (a setpoint sent late) while the vehicle stayed under
    offboard control: the trial's data are spoiled, the vehicle is not in danger, and the
    campaign flies the trial again (``flight.paused_trial_retries``)."""


class UpdateInfeasible(GcsError, ValueError):
    """The setpoint limits admit no next input (box, step or deviation bound); names the limit."""


class PathError(GcsError, ValueError):
    """A file or directory named on the command line cannot be used as asked (missing, a
    directory where a file is expected or the other way round, not writable); names it."""


class MocapError(GcsError, RuntimeError):
    """The motion-capture server is unreachable, the reader failed, or the stream is unusable."""


class StudyError(GcsError, ValueError):
    """A study definition (YAML) or a study's options are malformed; names file and field."""


class ClusterError(GcsError, RuntimeError):
    """The Dask scheduler is unreachable or not a scheduler's address; names it."""

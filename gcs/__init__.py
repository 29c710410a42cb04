"""gcs: a ground-control-station CLI that learns a repeated manoeuvre with smoother-based ILC."""

__version__ = "0.1.0"

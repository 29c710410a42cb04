"""``python -m gcs`` runs the command line.

Guarded: the trial source's worker process is started with multiprocessing's "spawn", which
imports the parent's main module again (as ``__mp_main__``); unguarded, that import would run
the parent's command a second time in the worker, a second ground station on the same vehicle.
"""

from gcs.cli import app

if __name__ == "__main__":
    app(prog_name="gcs")

"""``python -m gcs`` runs the command line.

Guarded: a process started with multiprocessing's "spawn" (a local Dask cluster's workers,
for one) imports the parent's main module again as ``__mp_main__``; unguarded, that import
would run the parent's command a second time in the child.
"""

from gcs.cli import app

if __name__ == "__main__":
    app(prog_name="gcs")

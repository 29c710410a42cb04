"""``python -m gcs`` runs the command line."""

from gcs.cli import app

app(prog_name="gcs")

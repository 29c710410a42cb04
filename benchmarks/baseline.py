"""The code of another commit, for the benchmarks that measure today's code against it."""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def baseline_tree(commit: str) -> Path:
    """A detached checkout of ``commit`` (made once, kept under the temporary directory)."""
    sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", commit], check=True,
                         capture_output=True, text=True).stdout.strip()  # fmt: skip
    path = Path(tempfile.gettempdir()) / f"gcs-bench-{sha}"
    if not (path / "gcs").is_dir():
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(path), sha],
                       check=True, capture_output=True)  # fmt: skip
    return path

"""Reading a YAML file with one-line errors. Light on imports: the mock drone uses it too."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from gcs.errors import GcsError

__all__ = ["read_yaml"]


def read_yaml(path: Path, error: type[GcsError]) -> Any:
    """Parse a YAML file; failures raise ``error`` naming the file (and the line).

    ``error``: exception class to raise (e.g. ProfileError, TrajectoryError).
    """
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start})") from exc
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" at line {mark.line + 1}" if mark is not None else ""
        reason = str(getattr(exc, "problem", None) or exc).splitlines()[0]
        raise error(f"{path}: malformed YAML{line}: {reason}") from exc

"""Paths named on the command line: packaged profiles and trajectories, and output checks.

Profiles and trajectories are found by name (``antx``, ``eight``) among those shipped with the
package, or by path. Every output a command will write (a file, a directory of figures, a new
run directory) is checked before the command does anything, so that a typo costs a line, not a
flight: nothing here creates, moves or writes anything except a probe file that is removed at
once (the only reliable test of writability: permissions, read-only mounts and immutable
directories all answer it alike, for root too).
"""

from __future__ import annotations

import os
import re
import tempfile
from importlib import resources
from pathlib import Path

from gcs.errors import PathError

__all__ = [
    "KINDS",
    "packaged_dir",
    "packaged_names",
    "resolve_named",
    "check_output_file",
    "check_output_dir",
    "check_new_dir",
    "check_writable_dir",
    "RUN_FILE",
]

#: What can be found by name, and the directory of the package that holds it.
KINDS = {"profile": "profiles", "trajectory": "trajectories"}
#: Names of the files a run directory records; never an output of anything else. They are the
#: names :class:`gcs.io.rundir.RunDir` gives them (tests/test_paths.py holds the two together),
#: spelled again here because that module builds on this one.
RUN_FILE = re.compile(
    r"^(manifest\.json|reference\.csv|identified\.yaml|floor\.json|"
    r"(setpoints|trial|estimate|mocap)-\d{3}\.csv|(trial|learn|again|session)-\d{3}\.json|"
    r"model-\d{3}\.yaml)$"
)


def packaged_dir(kind: str) -> Path:
    """The directory of the packaged files of ``kind``.

    ``kind``: ``"profile"`` or ``"trajectory"``.

    Returns: ``gcs/profiles`` or ``gcs/trajectories`` of the installed package (in a source
    checkout, symbolic links to the repository's top-level ``profiles/`` and ``trajectories/``: one
    copy of every file).
    """
    return Path(str(resources.files("gcs") / KINDS[kind]))


def packaged_names(kind: str) -> list[str]:
    """Names of the packaged files of ``kind`` (file names without ``.yaml``), sorted.

    ``kind``: ``"profile"`` or ``"trajectory"``.
    """
    directory = packaged_dir(kind)
    return sorted(p.stem for p in directory.glob("*.yaml")) if directory.is_dir() else []


def resolve_named(value: str | Path, kind: str, option: str) -> Path:
    """A profile or trajectory given by path or by packaged name.

    An existing file is taken as it is; otherwise a bare name (no directory part, with or
    without ``.yaml``) is looked up among the packaged files.

    ``kind``: ``"profile"`` or ``"trajectory"``. ``option``: the option's name for messages
    (``--profile``).

    Raises ``PathError``: neither an existing file nor a packaged name; or a directory.
    """
    text = str(value)
    if not text.strip():
        raise PathError(f"{option}: empty; give a {kind} name or a path")
    path = Path(text)
    if path.is_dir():
        raise PathError(f"{option} {text}: is a directory, not a {kind} file")
    if path.is_file():
        return path
    name = text[:-5] if text.endswith(".yaml") else text
    if name and "/" not in name and os.sep not in name and name not in (".", ".."):
        candidate = packaged_dir(kind) / f"{name}.yaml"
        if candidate.is_file():
            return candidate
    from gcs.io.suggest import did_you_mean

    names = packaged_names(kind)
    known = ", ".join(names) or "none"
    raise PathError(
        f"{option} {text}: no such file, and no packaged {kind} of that name ({known})"
        + did_you_mean(name, names)
    )


def _nearest_existing(path: Path, option: str) -> Path:
    """The nearest existing ancestor of ``path`` (itself excluded); it must be a directory."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise PathError(f"{option} {path}: {parent} is a file, not a directory")
            return parent
    raise PathError(f"{option} {path}: no existing parent directory")  # pragma: no cover


def check_writable_dir(directory: Path, what: str) -> None:
    """Refuse a directory that cannot be written into (probe file, removed at once).

    ``what``: how to name it in the message (``--plot plots``, ``run logs/x``).

    Raises ``PathError``: the probe cannot be created.
    """
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".gcs-probe-", suffix=".tmp")
    except OSError as exc:
        raise PathError(f"{what}: {directory} is not writable ({exc.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def check_output_file(path: Path, option: str) -> Path:
    """Check that ``path`` can be written as a file (missing directories will be created).

    ``option``: the option's name for messages (``--json``).

    Returns ``path``.

    Raises ``PathError``: a directory at ``path``, a file where a directory of it should be, a file
    a run directory records (``manifest.json``, ``trial-000.csv``, ...), or no permission.
    """
    path = Path(path)
    if path.is_dir():
        raise PathError(f"{option} {path}: is a directory, not a file")
    parent = path.absolute().parent
    if (parent / "manifest.json").is_file() and RUN_FILE.match(path.name):
        raise PathError(f"{option} {path}: is a file of the run directory {path.parent}")
    existing = parent if parent.is_dir() else _nearest_existing(path, option)
    check_writable_dir(existing, f"{option} {path}")
    return path


def check_output_dir(path: Path, option: str) -> Path:
    """Check that ``path`` is, or can be created as, a writable directory.

    ``option``: the option's name for messages (``--plot``).

    Returns ``path``.

    Raises ``PathError``: a file at ``path`` or above it, or no permission.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise PathError(f"{option} {path}: is a file, not a directory")
    existing = path if path.is_dir() else _nearest_existing(path, option)
    check_writable_dir(existing, f"{option} {path}")
    return path


def check_new_dir(path: Path, option: str) -> Path:
    """Check that ``path`` does not exist yet and can be created as a directory.

    ``path``: the directory to create (a new run). ``option``: the option's name for messages
    (``--run``).

    Returns ``path``.

    Raises ``PathError``: ``path`` exists, a file is in the way, or no permission.
    """
    path = Path(path)
    if path.exists() or path.is_symlink():
        what = "directory" if path.is_dir() else "file"
        raise PathError(f"{option} {path}: a {what} of that name exists already")
    check_writable_dir(_nearest_existing(path, option), f"{option} {path}")
    return path

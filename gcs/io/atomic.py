"""Files that appear whole or not at all, and files written once.

:func:`atomic_write_text` writes a temporary file beside the destination, flushes it to disk
and renames it into place (``os.replace``): a reader sees the old content or the new, never a
part. :func:`write_once` creates a file that must not exist with other content: recorded data
are never rewritten.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from gcs.errors import RunLogError

__all__ = ["atomic_write_text", "write_once", "FILE_MODE", "DIR_MODE"]


def _umask() -> int:
    mask = os.umask(0o022)  # the only way to read the umask is to set it
    os.umask(mask)
    return mask


#: Modes of the files and directories written here: what ``open()`` and ``mkdir()`` give
#: under the process's umask (``mkstemp`` and ``mkdtemp`` would make them owner-only).
FILE_MODE, DIR_MODE = 0o666 & ~_umask(), 0o777 & ~_umask()


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file + rename)."""
    path = Path(path)
    tmp = _temporary_copy(path, text)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _temporary_copy(path: Path, text: str) -> Path:
    """``text`` in a new hidden file beside ``path``, on disk (fsync), with open()'s mode."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, FILE_MODE)  # as open() would make it, not mkstemp's owner-only 0600
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return Path(tmp)


def write_once(path: Path, text: str) -> bool:
    """Write ``text`` to a new file ``path`` atomically; never replace different content.

    The file appears whole (temporary file, then a hard link that fails if the name exists)
    or not at all. If ``path`` holds exactly ``text`` already nothing is written (learning
    twice from the same trial is a no-op); different content is refused.

    Returns: True if the file was written, False if it held ``text`` already.

    Raises ``RunLogError``: ``path`` exists with other content.
    """
    path = Path(path)
    if path.is_dir():
        raise RunLogError(f"{path}: is a directory")
    tmp = _temporary_copy(path, text)
    try:
        try:
            os.link(tmp, path)  # atomic "create if absent"
            return True
        except FileExistsError:
            pass
        except OSError:  # a filesystem without hard links: check, then rename
            if not path.exists():
                os.replace(tmp, path)
                return True
    finally:
        tmp.unlink(missing_ok=True)
    try:
        same = path.read_bytes() == text.encode("utf-8")
    except OSError as exc:
        raise RunLogError(f"{path}: cannot read ({exc.strerror})") from exc
    if not same:
        raise RunLogError(
            f"{path}: exists with different content; recorded data are never rewritten"
        )
    return False

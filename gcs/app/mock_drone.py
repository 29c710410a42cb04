"""``gcs mock``: its files checked before the mock drone binds or runs.

The command and its options are the mock's own (:func:`gcs.mock.cli.mock_command`, also
``python -m gcs.mock``); ``gcs mock`` checks first what a mistyped option would otherwise make
it refuse later, or ignore: its settings file and where its statistics will go.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["check_mock_files"]


def check_mock_files(config: Path | None, stats_out: Path | None) -> None:
    """Refuse a mock profile that does not load, or a statistics file that cannot be written.

    Parameters
    ----------
    config : Path or None
        ``--config`` (a path; None for the mock's defaults).
    stats_out : Path or None
        ``--stats-out``.
    """
    from gcs.io.paths import check_output_file
    from gcs.mock.config import load_mock_config

    if config is not None:
        load_mock_config(config)
    if stats_out is not None:
        check_output_file(stats_out, "--stats-out")

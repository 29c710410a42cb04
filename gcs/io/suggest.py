"""Did you mean ...? The closest known name to a mistyped one, for one-line refusals."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["did_you_mean"]


def did_you_mean(word: str, known: Iterable[str]) -> str:
    """``"; did you mean 'antx'?"`` for the known name closest to ``word``, else ``""``.

    Closeness is :func:`difflib.get_close_matches` (ratio at least 0.6), case-insensitive.

    ``word``: what was typed (a field, a packaged name). ``known``: the names that would have been
    accepted.

    Returns: the suffix for a refusal's line (empty when no known name is close).
    """
    names = {name.lower(): name for name in known}
    close = difflib.get_close_matches(word.lower(), list(names), n=1)
    return f"; did you mean '{names[close[0]]}'?" if close else ""

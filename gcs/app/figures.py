"""Figures to files: the one place a matplotlib figure becomes PNG bytes or a PNG file.

Shared by the report (:mod:`gcs.app.report_figures`, :mod:`gcs.app.report_html`) and the
identification (:mod:`gcs.app.identify_figures`); it knows nothing of runs or learning.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

__all__ = ["figure_png", "save_figure", "DPI"]

#: Resolution of every PNG written [dots per inch].
DPI = 110


def figure_png(fig: Any) -> bytes:
    """A matplotlib figure as PNG bytes; the figure is closed."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=DPI)
    plt.close(fig)
    return buf.getvalue()


def save_figure(fig: Any, path: Path) -> Path:
    """Write a matplotlib figure (PNG, SVG, PDF) atomically (temporary file + rename), close it.

    ``path``: destination; its extension is the format (.png, .svg, .pdf).
    """
    import matplotlib.pyplot as plt

    tmp = path.with_name(f".{path.name}.tmp{path.suffix or '.png'}")
    fig.tight_layout()
    fig.savefig(tmp, dpi=DPI)
    plt.close(fig)
    tmp.replace(path)
    return path

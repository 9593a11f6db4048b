"""Figures and numbers in reports: saving matplotlib figures, PNGs as data URIs, numbers as text.

Figures are made with matplotlib's object API (`matplotlib.figure.Figure`), never
through pyplot's global state, so importing uwlab leaves a notebook's backend alone and needs no screen."""

from __future__ import annotations

import base64
import math
from pathlib import Path

from matplotlib.figure import Figure

__all__ = ["Figure", "number_text", "png_data_uri", "save_figure"]


def save_figure(fig: Figure, path: Path, dpi: int = 110) -> Path:
    """Lay out and write `fig` as PNG; returns `path`."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    return path


def png_data_uri(png: bytes) -> str:
    """A PNG as a ``data:`` URI, for self-contained HTML (the report, the EMVA datasheet)."""
    return "data:image/png;base64," + base64.b64encode(png).decode()


def number_text(value: float | None, spec: str = ".4g") -> str:
    """A number as the reports print it: ``format(value, spec)``, "—" when there is none or it is not finite.

    >>> number_text(0.123456), number_text(None), number_text(float("nan"), ".2f")
    ('0.1235', '—', '—')
    """
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:{spec}}"

"""Saving matplotlib figures. Figures are made with matplotlib's object API (`matplotlib.figure.Figure`), never
through pyplot's global state, so importing uwlab leaves a notebook's backend alone and needs no screen."""
from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

__all__ = ["Figure", "save_figure"]


def save_figure(fig: Figure, path: Path, dpi: int = 110) -> Path:
    """Lay out and write `fig` as PNG; returns `path`."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    return path

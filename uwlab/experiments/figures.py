"""Figures and numbers in reports: matplotlib figures as PNG (`figure_png`, `save_figure`), PNGs as data URIs,
numbers as text, and the rules every report figure follows.

Figures are made with matplotlib's object API (`Figure`, a `matplotlib.figure.Figure`), never through pyplot's
global state, so importing uwlab leaves a notebook's backend alone and needs no screen. Every ``plot_*`` function
returns its laid-out `Figure`, which a notebook shows inline; the PNG files, the report and the datasheet turn it into
PNG here, with the size and resolution each output has always had.

Rules (`PALETTE`, `log_ticks`, `TICK_PT`, `LABEL_PT`): colours from the Okabe–Ito palette, distinguishable with
every common colour-vision deficiency (Okabe & Ito, "Color Universal Design", 2008; Wong, Nature Methods 8, 441,
2011); log axes ticked at every decade and its 2 and 5 multiples, labelled as plain numbers; text at least
`TICK_PT` points (at the reports' sizes, ≥ 11 px on a 1400 px page); a model drawn over the measurements it is
compared with; data beyond an axis drawn at its edge as a marker labelled with its value."""

from __future__ import annotations

import base64
import io
import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path

import matplotlib.figure
from matplotlib.axis import Axis
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

__all__ = [
    "LABEL_PT",
    "PALETTE",
    "TICK_PT",
    "DrawnOnDemand",
    "Figure",
    "figure_png",
    "log_ticks",
    "number_text",
    "png_data_uri",
    "save_figure",
]

PALETTE = {  # Okabe–Ito
    "black": "#000000",
    "orange": "#E69F00",
    "sky": "#56B4E9",
    "green": "#009E73",
    "yellow": "#F0E442",
    "blue": "#0072B2",
    "vermillion": "#D55E00",
    "purple": "#CC79A7",
}
TICK_PT = 11
LABEL_PT = 12


class Figure(matplotlib.figure.Figure):
    """A matplotlib Figure that a notebook shows inline as it is (IPython's ``_repr_png_``). A figure made without
    pyplot is unknown to the inline backend's display hook, which would print only ``<Figure size ...>``; this
    one draws itself, cropped to what is drawn as the inline backend does, and is otherwise matplotlib's own.

    >>> fig = Figure(figsize=(2, 1))
    >>> _ = fig.subplots().plot([0, 1], [0, 1])
    >>> fig._repr_png_()[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
    True
    """

    def _repr_png_(self) -> bytes:
        return figure_png(self, tight_bbox=True)


class DrawnOnDemand(Mapping[str, Figure]):
    """Figures by name, each drawn when it is first asked for and kept: what the API's ``figures()`` return, so that
    a notebook cell showing one figure does not draw the others (a fit's corner plot takes ~2 s). A read-only
    mapping; ``dict(figures)`` draws them all.

    >>> figures = DrawnOnDemand([("empty", lambda: Figure(figsize=(1, 1)))])
    >>> list(figures), figures
    (['empty'], <figures: empty>)
    >>> figures["empty"] is figures["empty"]
    True
    """

    def __init__(self, makers: Iterable[tuple[str, Callable[[], Figure]]]):
        self._makers = dict(makers)
        self._drawn: dict[str, Figure] = {}

    def __getitem__(self, name: str) -> Figure:
        if name not in self._drawn:
            self._drawn[name] = self._makers[name]()
        return self._drawn[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._makers)

    def __len__(self) -> int:
        return len(self._makers)

    def __repr__(self) -> str:
        return f"<figures: {', '.join(self._makers)}>"


def log_ticks(axis: Axis, max_labelled_decades: float = 3.0) -> None:
    """Major ticks of a log `axis` at 1, 2 and 5 times each decade, labelled as plain numbers ("0.2", "50",
    "2000"); beyond `max_labelled_decades` of range (where the labels would collide) the 2 and 5 ticks stay but
    only the decades are labelled; no minor labels.

    >>> ax = Figure().add_subplot()
    >>> ax.set_xscale("log"); _ = ax.set_xlim(10, 1000); log_ticks(ax.xaxis)
    >>> [ax.xaxis.get_major_formatter()(v, 0) for v in ax.xaxis.get_majorticklocs() if 10 <= v <= 1000]
    ['10', '20', '50', '100', '200', '500', '1000']
    """
    axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0), numticks=30))

    def label(value: float, _position: object) -> str:
        lo, hi = sorted(axis.get_view_interval())
        wide = lo > 0 and math.log10(hi / lo) > max_labelled_decades
        decade = math.isclose(10 ** round(math.log10(value)), value, rel_tol=1e-9) if value > 0 else False
        return f"{value:.6g}" if decade or not wide else ""

    axis.set_major_formatter(FuncFormatter(label))
    axis.set_minor_formatter(NullFormatter())


def figure_png(fig: matplotlib.figure.Figure, dpi: int = 110, *, tight_bbox: bool = False) -> bytes:
    """`fig` as PNG at `dpi`, cropped to what is drawn when `tight_bbox` (a figure laid out by its own grid rather
    than ``tight_layout``): what `save_figure` writes and the report and datasheet embed.

    >>> figure_png(Figure(figsize=(1, 1)), dpi=20)[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight" if tight_bbox else None)
    return buffer.getvalue()


def save_figure(fig: matplotlib.figure.Figure, path: Path, dpi: int = 110, *, tight_bbox: bool = False) -> Path:
    """Write `fig` as the PNG of `figure_png` to `path`; returns `path`."""
    path.write_bytes(figure_png(fig, dpi, tight_bbox=tight_bbox))
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

"""Progress that fits the place: the one helper every progress display goes through.

- In a Jupyter kernel: ``tqdm.auto`` (a widget bar with ipywidgets installed, else tqdm's text bar).
- On a terminal (the stream is a TTY): a tqdm text bar on stderr, removed when done unless ``leave``.
- Anywhere else (stderr redirected to a file or a pipe, a test's captured stream): nothing — no bar escape codes in
  a log (``uwlab demo 2> file`` leaves the file empty of progress).

A bar is drawn by the first `Bar.update`, so a command that fails on bad input before any work draws nothing.

>>> with bar(total=3, desc="points", enabled=False) as b:
...     b.update(3)
>>> b.n
3
>>> where(stream=None, enabled=False)
'off'
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from types import TracebackType
from typing import IO, Any, Literal

Place = Literal["notebook", "terminal", "off"]


def in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (an IPython shell with an ``IPKernelApp``), as ``tqdm.auto``
    decides."""
    ipython = sys.modules.get("IPython")
    if ipython is None:
        return False
    try:
        shell = ipython.get_ipython()
    except Exception:  # an IPython without a shell
        return False
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})


def where(stream: IO[str] | None = None, enabled: bool = True) -> Place:
    """Where progress goes: ``"notebook"``, ``"terminal"`` (`stream`, default stderr, is a TTY) or ``"off"``."""
    if not enabled:
        return "off"
    if in_notebook():
        return "notebook"
    stream = sys.stderr if stream is None else stream
    try:
        return "terminal" if stream.isatty() else "off"
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return "off"


class Bar:
    """A progress bar with tqdm's small interface (`update`, `set_postfix_str`, `set_position`, `close`; a context
    manager), drawn where `where` says, opened at its first update."""

    def __init__(
        self,
        total: float | None = None,
        desc: str = "",
        unit: str = "it",
        *,
        enabled: bool = True,
        leave: bool = False,
        stream: IO[str] | None = None,
        bar_format: str | None = None,
        initial: float = 0,
    ) -> None:
        self.total = total
        self.desc = desc
        self.unit = unit
        self.n: float = initial
        self.place: Place = where(stream, enabled)
        self._stream = stream
        self._leave = leave
        self._bar_format = bar_format
        self._tqdm: Any = None

    def _bar(self) -> Any:
        if self._tqdm is None and self.place != "off":
            if self.place == "notebook":
                from tqdm.auto import tqdm
            else:
                from tqdm import tqdm
            self._tqdm = tqdm(
                total=self.total,
                desc=self.desc,
                unit=self.unit,
                leave=self._leave,
                file=self._stream if self._stream is not None else sys.stderr,
                bar_format=self._bar_format,
                initial=self.n,
            )
        return self._tqdm

    def update(self, n: float = 1) -> None:
        """Advance by `n`."""
        shown = self._bar()
        self.n += n
        if shown is not None:
            shown.update(n)

    def set_position(self, n: float, postfix: str | None = None) -> None:
        """Set the count to `n` (a quantity that is not a sum of steps, e.g. a chain's length in τ)."""
        self.n = n
        shown = self._bar()
        if shown is not None:
            shown.n = n
            if postfix is not None:
                shown.set_postfix_str(postfix, refresh=False)
            shown.refresh()

    def set_postfix_str(self, text: str) -> None:
        """Text shown after the bar (the latest point, ...)."""
        if self._tqdm is not None:
            self._tqdm.set_postfix_str(text, refresh=False)

    def close(self) -> None:
        if self._tqdm is not None:
            self._tqdm.close()

    def __enter__(self) -> Bar:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.close()


def bar(
    total: float | None = None,
    desc: str = "",
    unit: str = "it",
    *,
    enabled: bool = True,
    leave: bool = False,
    stream: IO[str] | None = None,
    bar_format: str | None = None,
    initial: float = 0,
) -> Bar:
    """A `Bar` (module docstring): ``with bar(total=n, desc="sweep", unit="point") as b: ... b.update()``;
    `initial`: the count already done (a resumed sweep)."""
    return Bar(total, desc, unit, enabled=enabled, leave=leave, stream=stream, bar_format=bar_format, initial=initial)


TAU_TARGET = 50  # the fit runs until the chain is this many autocorrelation times long


def tau_bar(desc: str, enabled: bool = True, stream: IO[str] | None = None) -> tuple[Bar, Callable[[int, float], None]]:
    """A bar over an MCMC chain's length in autocorrelation times (a fit stops at 50 τ) and the
    ``progress(steps, tau_multiple)`` callback the fit reports to (`uwlab.experiments.calibration.fit.run_fit`)."""
    shown = bar(
        total=TAU_TARGET,
        desc=desc,
        unit="τ",
        enabled=enabled,
        stream=stream,
        bar_format="{desc}: {n:.0f}/{total} τ |{bar}| {elapsed} {postfix}",
    )

    def update(steps: int, tau_multiple: float) -> None:
        shown.set_position(min(float(TAU_TARGET), tau_multiple), f"{steps} steps")

    return shown, update

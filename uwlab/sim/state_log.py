"""The simulators' own record of their true state over time: a JSON-lines file per instrument.

Tests and fault campaigns compare what a sweep recorded against this log, which the code under test
never reads. One line per event, appended (``O_APPEND``, one ``write`` per line, so the processes of a
restarted simulator append to the same file safely)::

    {"t_ns": 1718000000123456789, "event": "command", "on": true, "level": 0.5, "flux_fraction": 0.218}

``t_ns`` is wall-clock time (``time.time_ns``), the clock of a dataset's ``*_t_*_ns`` columns. ``event`` is
``power-on`` (start, ``*RST`` or a reset), ``command`` (a setting changed), ``read`` (the spectrometer took a
reading: its settings and the light state it saw) or ``power-lost`` (the process was killed; written by
whoever killed it). Every line carries the instrument's full state after the event.

The log is appended to without waiting (a FIFO planted at its path with no reader is an `OSError`, never a
blocked instrument) and read through the one bounded regular-file reader (`uwlab.model.data.read_text`).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from uwlab.model.data import MAX_JSON_BYTES, read_text


class StateLog:
    """Append-only JSON-lines log of one instrument's state."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    def append(self, event: str, **state: object) -> None:
        line = json.dumps({"t_ns": time.time_ns(), "event": event, **state}, separators=(",", ":")) + "\n"
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
        try:
            os.write(fd, line.encode())
        finally:
            os.close(fd)

    def entries(self) -> list[dict]:
        """Every event so far, in time order (a missing file: none)."""
        if not os.path.lexists(self.path):
            return []
        text = read_text(self.path, "state log", MAX_JSON_BYTES, "state log")
        return sorted((json.loads(line) for line in text.splitlines() if line.strip()), key=lambda e: e["t_ns"])


def states_during(entries: list[dict], t_start_ns: int, t_end_ns: int) -> list[dict]:
    """The states in force at any time in [t_start_ns, t_end_ns]: the last event at or before the start,
    then every event up to the end. ``read`` events describe a reading, not a change, and are left out."""
    changes = [e for e in entries if e["event"] != "read"]
    before = [e for e in changes if e["t_ns"] <= t_start_ns]
    during = [e for e in changes if t_start_ns < e["t_ns"] <= t_end_ns]
    return before[-1:] + during


def reads_during(entries: list[dict], t_start_ns: int, t_end_ns: int) -> list[dict]:
    """The ``read`` events logged within [t_start_ns, t_end_ns]."""
    return [e for e in entries if e["event"] == "read" and t_start_ns <= e["t_ns"] <= t_end_ns]

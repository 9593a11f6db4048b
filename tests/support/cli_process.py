"""The ``uwlab`` command as a real process (``python -m uwlab.cli.main``) for the end-to-end tests.

A process runs in a session of its own, so that a signal to its process group reaches it and the simulators it
starts as a terminal's Ctrl-C would, and a hung one is killed with everything it started. Its output is text
(UTF-8, undecodable bytes as backslash escapes)."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO

from uwlab.errors import ConfigError
from uwlab.experiments.dataset import Dataset

TIMEOUT_S = 180


def uwlab(*args, **popen) -> subprocess.Popen:
    """``uwlab ARGS`` started (arguments: strings, paths or bytes), stdout and stderr piped; ``popen``: more
    `subprocess.Popen` arguments (``env``, ``preexec_fn``, ...)."""
    argv = [a if isinstance(a, bytes) else str(a) for a in args]
    return subprocess.Popen(
        [sys.executable, "-m", "uwlab.cli.main", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        encoding="utf-8",
        errors="backslashreplace",
        start_new_session=True,
        **popen,
    )


def finish(process: subprocess.Popen, timeout_s: float = TIMEOUT_S) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of a process `uwlab` started; its process group is killed if it has not exited
    after ``timeout_s``."""
    try:
        out, err = process.communicate(timeout=timeout_s)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
    return process.returncode, out, err


def run(*args, timeout_s: float = TIMEOUT_S, **popen) -> tuple[int, str, str]:
    """``uwlab ARGS`` to its end: exit code, stdout and stderr."""
    return finish(uwlab(*args, **popen), timeout_s)


def wait_until(
    condition: Callable[[], bool],
    process: subprocess.Popen,
    what: str,
    every_s: float = 0.05,
    timeout_s: float = TIMEOUT_S,
) -> None:
    """Return once ``condition()`` holds (tried every ``every_s``); fail if ``process`` exits before, or after
    ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        assert process.poll() is None, f"exited ({process.returncode}) before {what}"
        time.sleep(every_s)
    raise AssertionError(f"timed out waiting until {what}")


def read_line(stream: IO[str], timeout_s: float, what: str) -> str:
    """The next line a process writes to ``stream`` (its stdout or stderr); fail if none comes within
    ``timeout_s``."""
    ready, _, _ = select.select([stream], [], [], timeout_s)
    assert ready, f"no line from {what} within {timeout_s} s"
    return stream.readline()


def points_recorded(root: Path) -> int:
    """The points a running sweep has recorded so far into the dataset at ``root`` (0 while it is not a dataset:
    before it exists, and while a sweep replaces an empty one left by an interrupted run, whose metadata can vanish
    between a check for it and its read)."""
    try:
        return len(Dataset.open(root).completed())
    except ConfigError:
        return 0

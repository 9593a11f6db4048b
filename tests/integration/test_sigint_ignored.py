"""Ctrl-C works whatever SIGINT disposition `uwlab` inherits: started with SIGINT ignored (as a background job of a
non-interactive shell is), a SIGINT still ends it with the one line `interrupted` and exit code 130."""

from __future__ import annotations

import signal
import subprocess
import sys

from tests.support.paths import EXAMPLE


def test_sigint_interrupts_even_when_the_parent_ignored_it():
    ignore = lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)  # noqa: E731 (the child's disposition at exec)
    process = subprocess.Popen(
        [sys.executable, "-m", "uwlab.cli.main", "explore", str(EXAMPLE), "--no-browser", "--json", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ignore,
    )
    try:
        assert process.stdout.readline().startswith('{"url"')  # serving: well past start-up
        process.send_signal(signal.SIGINT)
        code = process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    err = process.stderr.read()
    assert code == 130 and err.strip().splitlines()[-1] == "uwlab explore: interrupted"

"""`uwlab console --sim` as a real process on 127.0.0.1 for the tests: started with ``--json --port 0 --no-browser``,
its URL read from the first line, stopped with Ctrl-C (SIGINT)."""

from __future__ import annotations

import json
import select
import signal
import subprocess
import sys

START_TIMEOUT_S = 120


class Console:
    def __init__(self, *args: str):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "uwlab.cli.main", "console", "--no-browser", "--json", "--port", "0", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        ready, _, _ = select.select([self.process.stdout], [], [], START_TIMEOUT_S)
        line = self.process.stdout.readline() if ready else ""
        if not line:
            self.stop()
            raise RuntimeError(f"uwlab console did not start: {self.process.stderr.read()}")
        self.url = json.loads(line)["url"]

    def stop(self) -> tuple[int, str]:
        """Ctrl-C; returns (exit code, stderr)."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=30)
        err = self.process.stderr.read()
        self.process.stdout.close()
        self.process.stderr.close()
        return self.process.returncode, err

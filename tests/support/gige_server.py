"""`uwlab sim camera --gige` in a subprocess on its own loopback address, for tests (always stopped)."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys

_hosts = itertools.count(20 + os.getpid() % 100)


class Server:
    """The GigE Vision camera server on a fresh loopback address (or on ``address``: a restart)."""

    def __init__(self, *extra: str, address: str | None = None):
        self.extra = extra
        for _ in range(5):
            self.address = address or f"127.0.{os.getpid() % 200 + 1}.{next(_hosts) % 250 + 2}"
            self.proc = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "uwlab.cli.main",
                    "sim",
                    "camera",
                    "--gige",
                    "--json",
                    "--address",
                    self.address,
                    *extra,
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            line = self.proc.stdout.readline()
            if line:
                self.info = json.loads(line)
                return
            err = self.stop()
        raise RuntimeError(f"GigE sim server did not start: {err}")

    def restarted(self) -> Server:
        """A new server process on the same address (the old one must be gone)."""
        return Server(*self.extra, address=self.address)

    def kill(self) -> None:
        """SIGKILL: the device vanishes without a goodbye."""
        self.proc.kill()
        self.stop()

    def freeze(self) -> None:
        self.proc.send_signal(signal.SIGSTOP)

    def thaw(self) -> None:
        self.proc.send_signal(signal.SIGCONT)

    def stop(self) -> str:
        """Stop the server (SIGTERM, then SIGKILL); returns what it wrote to stderr."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGCONT)
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        err = "" if self.proc.stderr.closed else self.proc.stderr.read()
        for stream in (self.proc.stdout, self.proc.stderr):
            stream.close()
        return err

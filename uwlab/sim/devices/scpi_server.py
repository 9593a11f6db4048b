"""Put a simulated SCPI instrument on the wire, the ways real ones are reached, in a thread of this process.

- ``"tcp"``: raw SCPI over a TCP socket on the loopback, as LXI instruments serve it on port 5025 (Keysight and
  RIGOL manuals: "Sockets", port 5025). VISA resource ``TCPIP::127.0.0.1::PORT::SOCKET``; a socket session has no
  end-of-message flag, so the client sets ``read_termination="\\n"`` (pyvisa-py documentation, "SOCKET").
- ``"pty"``: a serial line on a real pseudo-terminal (`uwlab.sim.devices.serial_sim.PtyPort`, raw mode), as an RS-232
  or USB-serial instrument is reached; VISA resource ``ASRL/dev/pts/N::INSTR`` (pyvisa-py with pyserial).

Lines end with ``\\n``; each reaches the instrument as received, byte for byte (decoded as Latin-1, so
``line.encode("latin-1")`` gives the bytes back; a ``\\r`` before the ``\\n`` is kept). A line longer than
`MAX_LINE_BYTES` is dropped, recorded as ``<line longer than N bytes>`` and answered with nothing (the instrument
queues ``-223``, too much data).
The instrument is anything with ``handle(line) -> str | None`` (`uwlab.sim.devices.supply.SupplyTwin`).
"""

from __future__ import annotations

import os
import socket
import socketserver
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Protocol

from uwlab.sim.devices.serial_sim import PtyPort

TRANSPORTS = ("tcp", "pty")
MAX_LINE_BYTES = 4096
POLL_S = 0.05


class LineInstrument(Protocol):
    def handle(self, line: str) -> str | None: ...

    def overlong(self, limit: int) -> None: ...


class LineSplitter:
    """Bytes in, complete lines out (bounded: an over-long line is reported once and skipped to its end)."""

    def __init__(self, instrument: LineInstrument):
        self.instrument = instrument
        self._buffer = b""
        self._skipping = False

    def feed(self, data: bytes) -> bytes:
        """The replies (terminated) to the complete lines in ``data`` and what came before it."""
        self._buffer += data
        replies = []
        while b"\n" in self._buffer:
            raw, _, self._buffer = self._buffer.partition(b"\n")
            if self._skipping or len(raw) > MAX_LINE_BYTES:
                self._skipping = False
                self.instrument.overlong(MAX_LINE_BYTES)
                continue
            reply = self.instrument.handle(raw.decode("latin-1"))
            if reply is not None:
                replies.append(reply.encode("ascii", "replace") + b"\n")
        if len(self._buffer) > MAX_LINE_BYTES:
            self._buffer = b""
            self._skipping = True
        return b"".join(replies)


@contextmanager
def serve(instrument: LineInstrument, transport: str = "tcp", port: int = 0) -> Iterator[str]:
    """Serve ``instrument`` in a thread and yield its VISA resource string; stop and clean up on exit.

    ``port`` (TCP only): 0 picks a free one; 5025 is the LXI convention (needs it free)."""
    if transport == "tcp":
        with _serve_tcp(instrument, port) as resource:
            yield resource
    elif transport == "pty":
        with _serve_pty(instrument) as resource:
            yield resource
    else:
        raise ValueError(f"transport must be one of {', '.join(TRANSPORTS)}, got {transport!r}")


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True
    block_on_close = False

    def __init__(self, address, instrument: LineInstrument):
        self.instrument = instrument
        self.connections: set[socket.socket] = set()
        self.lock = threading.Lock()
        super().__init__(address, _Connection)


class _Connection(socketserver.BaseRequestHandler):
    server: _Server

    def handle(self) -> None:
        with self.server.lock:
            self.server.connections.add(self.request)
        splitter = LineSplitter(self.server.instrument)
        try:
            while data := self.request.recv(4096):
                replies = splitter.feed(data)
                if replies:
                    self.request.sendall(replies)
        except OSError:
            pass  # the client went away, or the server is closing the connection
        finally:
            with self.server.lock:
                self.server.connections.discard(self.request)


@contextmanager
def _serve_tcp(instrument: LineInstrument, port: int) -> Iterator[str]:
    server = _Server(("127.0.0.1", port), instrument)
    thread = threading.Thread(target=server.serve_forever, args=(POLL_S,), name="scpi-tcp", daemon=True)
    thread.start()
    try:
        yield f"TCPIP::127.0.0.1::{server.server_address[1]}::SOCKET"
    finally:
        server.shutdown()
        with server.lock:
            for connection in list(server.connections):
                try:
                    connection.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        server.server_close()
        thread.join()


@contextmanager
def _serve_pty(instrument: LineInstrument) -> Iterator[str]:
    stop = threading.Event()
    with tempfile.TemporaryDirectory(prefix="uwlab-twin-") as directory:
        pty = PtyPort(Path(directory) / "instrument")
        splitter = LineSplitter(instrument)

        def run() -> None:
            while not stop.is_set():
                replies = splitter.feed(pty.read(POLL_S))
                if replies:
                    pty.write(replies)

        thread = threading.Thread(target=run, name="scpi-pty", daemon=True)
        thread.start()
        try:
            yield f"ASRL{os.readlink(pty.link)}::INSTR"
        finally:
            stop.set()
            thread.join()
            pty.close()

"""Line transport over pyserial: framing, timeouts, bounded retries and recovery (docs/serial-protocol.md).

One `LineTransport` owns one port. Every command is one line; every reply is one line (or, for a
block, a header, data lines and ``END``). What is recovered, each within ``1 + retries`` attempts:

- no reply, or a partial line followed by silence (timeout) → the command is sent again;
- garbage (non-ASCII, control bytes, wrong reply type) → input discarded, command sent again;
- after a failed attempt, a reopen, and a reply that needed more than one attempt, input is read and
  discarded until the line has been quiet for ``QUIET_S``: a late reply to an abandoned attempt must not be
  taken for the answer to the next command (the protocol's replies carry no sequence number);
- ``ERR 200`` (busy) → sent again; any other ``ERR`` is reported at once;
- a banner (``# ...``, the instrument has reset, during a command or between commands) → ``on_recover``
  is called (drivers re-apply and verify their settings), then the command is sent again;
- the port disappearing (read/write/open errors) → closed and reopened until ``reopen_s`` has passed,
  ``on_recover`` called (whatever answers on the reopened port may have restarted), then the command is
  sent again.

`LineTransport.recoveries` counts the resets and reopens seen, nested ones (during ``on_recover``) included.

Giving up raises one `DeviceError` naming the port and the command. All commands of the protocol are
idempotent, so repeating one is safe.
"""

from __future__ import annotations

import termios
import time
from functools import partial
from typing import TypeVar, overload
from collections.abc import Callable

import serial

from uwlab.drivers.serial.protocol import (
    BLOCK_END,
    MAX_LINE_BYTES,
    RETRYABLE_ERROR_CODES,
    TERMINATOR,
    Reply,
    ReplyParseError,
    decode_line,
    parse_block_header,
    parse_reply,
)
from uwlab.errors import ConfigError, DeviceError

BAUDRATE = 115200
PORT_ERRORS = (serial.SerialException, OSError, termios.error)
QUIET_S = 0.2
T = TypeVar("T")


class _Retry(Exception):
    """A failed attempt that may succeed if the command is sent again."""


class _Reset(_Retry):
    """The instrument announced a reset (banner) instead of replying."""


class _PortLost(_Retry):
    """The port raised an OS-level error: it has vanished."""


class _Refused(Exception):
    """The instrument replied ``ERR <code> <message>`` with a code that retrying cannot fix."""


class LineTransport:
    """Send commands and read replies on one serial port, with bounded retries.

    ``port`` is anything `serial.serial_for_url` opens (a device path, a symlink to one, or a URL); it is
    locked (``flock``) while open, so two programs cannot interleave commands on one instrument.
    ``timeout_s`` bounds each reply, ``retries`` the extra attempts per command, ``reopen_s`` the time
    allowed for a vanished port to come back. ``on_recover`` is called after an unrequested reset or a
    reopen, before the interrupted command is sent again.
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = BAUDRATE,
        timeout_s: float = 1.0,
        retries: int = 3,
        reopen_s: float = 5.0,
        on_recover: Callable[[], None] | None = None,
    ):
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise ConfigError("retries", retries, "must be an integer >= 0")
        if not (timeout_s > 0 and reopen_s >= 0):
            raise ConfigError("timeout_s", timeout_s, "timeout must be > 0 and reopen time >= 0")
        self.port = port
        self.baudrate = baudrate
        self.timeout_s = timeout_s
        self.retries = retries
        self.reopen_s = reopen_s
        self.on_recover = on_recover
        self.recoveries = 0
        self._serial: serial.SerialBase | None = None
        self._buffer = b""
        self._restoring = False

    def open(self) -> LineTransport:
        try:
            self._serial = self._open_port()
        except PORT_ERRORS as exc:
            raise DeviceError(f"{self.port}: cannot open port ({exc})") from None
        return self

    def close(self) -> None:
        if self._serial is not None:
            try:
                self._serial.close()
            except PORT_ERRORS:
                pass
        self._serial = None
        self._buffer = b""

    def __enter__(self) -> LineTransport:
        return self if self._serial is not None else self.open()

    def __exit__(self, *exc_info) -> None:
        self.close()

    def command(self, command: str) -> None:
        """Send a setting command; the instrument must reply ``OK``."""
        self._transact(command, lambda deadline: self._expect(self._read_reply(deadline), "ok"), self.timeout_s)

    @overload
    def query(self, command: str) -> str: ...
    @overload
    def query(self, command: str, parse: Callable[[str], T]) -> T: ...
    def query(self, command: str, parse: Callable[[str], object] = str) -> object:
        """Send a query; returns its value text through ``parse`` (a `ReplyParseError` there is retried)."""
        return self._transact(
            command, lambda deadline: parse(self._expect(self._read_reply(deadline), "value").text), self.timeout_s
        )

    def query_block(self, command: str, timeout_s: float, parse: Callable[[list[str]], T]) -> tuple[bool, T]:
        """Send a block query (``BEGIN <n> <flag>`` … ``END``); returns (flag, ``parse(data lines)``)."""
        return self._transact(command, lambda deadline: self._read_block(deadline, parse), timeout_s)

    def reset(self) -> None:
        """``*RST``: the banner it causes is expected and does not trigger ``on_recover``."""
        self._transact("*RST", self._read_ok_after_banner, self.timeout_s)

    def _transact(self, command: str, receive: Callable[[float], T], timeout_s: float) -> T:
        attempts = 1 + self.retries
        last: Exception | None = None
        for attempt in range(attempts):
            try:
                self._ensure_open(command)
                self._drain_unsolicited()
                self._send(command)
                result = receive(time.monotonic() + timeout_s)
                if attempt:
                    self._wait_quiet()
                return result
            except _Reset as exc:
                last = exc
                self._restore()
            except _PortLost as exc:
                last = exc
                self._reopen(command)
                self._wait_quiet()
                self._restore()
            except (_Retry, ReplyParseError) as exc:
                last = exc
                self._wait_quiet()
            except _Refused as exc:
                raise DeviceError(f"{self.port}: command {command!r} refused by the instrument: {exc}") from None
        raise DeviceError(f"{self.port}: command {command!r} failed after {attempts} attempts (last: {last})")

    def _port(self) -> serial.SerialBase:
        """The open port; a transport closed meanwhile (e.g. by ``on_recover``) has lost it."""
        if self._serial is None:
            raise _PortLost("port closed")
        return self._serial

    def _open_port(self) -> serial.SerialBase:
        return serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=self.timeout_s, exclusive=True)

    def _ensure_open(self, command: str) -> None:
        if self._serial is None:
            self._reopen(command)
            self._restore()

    def _reopen(self, command: str) -> None:
        self.close()
        deadline = time.monotonic() + self.reopen_s
        while True:
            try:
                self._serial = self._open_port()
                return
            except PORT_ERRORS as exc:
                if time.monotonic() > deadline:
                    raise DeviceError(
                        f"{self.port}: port vanished during command {command!r} and did not come back "
                        f"within {self.reopen_s:g} s ({exc})"
                    ) from None
                time.sleep(0.05)

    def _restore(self) -> None:
        self.recoveries += 1
        if self.on_recover is None or self._restoring:
            return
        self._restoring = True
        try:
            self.on_recover()
        finally:
            self._restoring = False

    def _io(self, operation: Callable[[], T]) -> T:
        try:
            return operation()
        except PORT_ERRORS as exc:
            raise _PortLost(f"port error: {exc}") from None

    def _drain_unsolicited(self) -> None:
        """Discard pending input; a banner among it means the instrument reset since the last reply."""
        port = self._port()
        pending = self._buffer + self._io(lambda: port.read(port.in_waiting))
        self._buffer = b""
        for raw in pending.split(TERMINATOR):
            try:
                banner = parse_reply(raw).kind == "banner"
            except ReplyParseError:
                continue
            if banner:
                self._restore()

    def _wait_quiet(self) -> None:
        """Collect input until none has arrived for ``QUIET_S`` (at most ``timeout_s + reopen_s``, for an
        instrument that never stops talking); the next command's `_drain_unsolicited` discards it, noting any
        banner. A port lost meanwhile is left to the next attempt."""
        give_up = time.monotonic() + self.timeout_s + self.reopen_s
        try:
            while time.monotonic() < give_up and (late := self._read_within(QUIET_S)):
                self._buffer += late
        except (*PORT_ERRORS, _PortLost):
            pass

    def _send(self, command: str) -> None:
        line = command.encode("ascii") + TERMINATOR
        port = self._port()
        self._io(lambda: (port.write(line), port.flush()))

    def _read_line(self, deadline: float) -> bytes:
        while TERMINATOR not in self._buffer:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                tail = f", partial line {self._buffer[:40]!r}" if self._buffer else ""
                self._buffer = b""
                raise _Retry(f"no reply within {self.timeout_s:g} s{tail}")
            if len(self._buffer) > MAX_LINE_BYTES:
                self._buffer = b""
                raise ReplyParseError(f"line longer than {MAX_LINE_BYTES} bytes")
            self._buffer += self._io(partial(self._read_within, remaining))
        line, _, self._buffer = self._buffer.partition(TERMINATOR)
        return line

    def _read_within(self, timeout_s: float) -> bytes:
        """What arrives within `timeout_s`; setting the timeout reconfigures the port (termios), which fails like
        a read when the port has just gone, so both are one I/O step (`_io`)."""
        port = self._port()
        port.timeout = timeout_s
        return port.read(max(1, port.in_waiting))

    def _read_reply(self, deadline: float) -> Reply:
        reply = parse_reply(self._read_line(deadline))
        if reply.kind == "banner":
            raise _Reset(f"instrument reset ({reply.text})")
        if reply.kind == "error" and reply.code in RETRYABLE_ERROR_CODES:
            raise _Retry(f"ERR {reply.code} {reply.text}")
        if reply.kind == "error":
            raise _Refused(f"ERR {reply.code} {reply.text}")
        return reply

    def _expect(self, reply: Reply, kind: str) -> Reply:
        if reply.kind != kind:
            raise ReplyParseError(f"expected a reply of type {kind!r}, got {reply.kind!r} {reply.text!r}")
        return reply

    def _read_ok_after_banner(self, deadline: float) -> None:
        while (reply := parse_reply(self._read_line(deadline))).kind == "banner":
            continue
        if reply.kind == "error":
            raise _Refused(f"ERR {reply.code} {reply.text}")
        self._expect(reply, "ok")

    def _read_block(self, deadline: float, parse: Callable[[list[str]], T]) -> tuple[bool, T]:
        n, flag = parse_block_header(self._expect(self._read_reply(deadline), "value").text)
        lines = [decode_line(self._read_line(deadline)) for _ in range(n)]
        end = decode_line(self._read_line(deadline))
        if end != BLOCK_END:
            raise ReplyParseError(f"expected {BLOCK_END!r} after {n} data lines, got {end!r}")
        return flag, parse(lines)

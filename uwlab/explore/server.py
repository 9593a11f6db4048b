"""The HTTP server under a guarded web application (`uwlab.explore.security.Guard`): uvicorn, with deadlines and
connection caps that an ASGI middleware cannot apply, since it runs only once a request has been read whole.

uvicorn has no timeout on receiving a request: its keep-alive timer (``timeout_keep_alive``) counts only the idle
time after a response and is reset by every byte received, so a client that opens connections and sends nothing, or
a request a byte at a time (slowloris), holds them for ever, before any token is checked. `GuardedH11Protocol`, a
subclass of uvicorn's h11 protocol (the same mitigation as hyper's ``header_read_timeout`` and Go's
``ReadHeaderTimeout``), adds:

- **Deadlines**: a request's line and headers must arrive within `Limits.header_timeout_s` of the connection (or of
  the previous response) and its body within `Limits.body_timeout_s` of its headers, however slowly the bytes come;
  else the connection is closed. The time the application takes to answer is not limited.
- **Connection caps**: at most `Limits.per_client` connections from one address and `Limits.max_connections` in
  all. A connection beyond a cap closes the oldest connection (of that address, or of anyone) that is not running a
  request — one waiting for its request or receiving it — so held connections never keep a new client out; when every
  connection is running a request the new one is closed.

h11's buffer limit (``h11_max_incomplete_event_size``) bounds a request line with its headers. uvicorn's
``limit_concurrency`` is not used: it counts connections, held ones included, and would answer 503 to everyone
once they reach it, where the caps close the held ones instead. Nothing here knows what the application is.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol


@dataclass(frozen=True)
class Limits:
    """How long a request may take to arrive and how many connections are kept (module docstring)."""

    header_timeout_s: float = 10.0
    body_timeout_s: float = 20.0
    per_client: int = 32
    max_connections: int = 256
    max_header_bytes: int = 16_384
    keep_alive_s: int = 5


# The phases of a connection, from the state h11 keeps of the client's side.
WAITING, RECEIVING, RUNNING = "waiting for a request", "receiving a request body", "running a request"


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with the deadlines and caps of `Limits` (module docstring); ``limits`` is set on a
    subclass by `server_config`."""

    limits = Limits()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._phase: str | None = None
        self._deadline: asyncio.TimerHandle | None = None
        self._opened = self.loop.time()
        self._enter_phase()
        self._cap()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._enter_phase()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._enter_phase()

    def connection_lost(self, exc: Exception | None) -> None:
        self._arm(None)
        super().connection_lost(exc)

    def _enter_phase(self) -> None:
        """Arm the deadline of the phase the connection is in, when it has just entered it."""
        if self.transport.is_closing():
            return
        state = self.conn.their_state
        phase = WAITING if state is h11.IDLE else RECEIVING if state is h11.SEND_BODY else RUNNING
        if phase == self._phase:
            return
        self._phase = phase
        timeout = {WAITING: self.limits.header_timeout_s, RECEIVING: self.limits.body_timeout_s}.get(phase)
        self._arm(timeout)

    def _arm(self, timeout: float | None) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
        self._deadline = None if timeout is None else self.loop.call_later(timeout, self._expired)

    def _expired(self) -> None:
        self._deadline = None
        if not self.transport.is_closing():
            self.transport.close()

    def _cap(self) -> None:
        """Keep the connections within `Limits.per_client` and `Limits.max_connections` (module docstring)."""
        host = self.client[0] if self.client else None
        mine = [c for c in self.connections if isinstance(c, GuardedH11Protocol) and not c.transport.is_closing()]
        for group, cap in (
            ([c for c in mine if c.client and c.client[0] == host], self.limits.per_client),
            (mine, self.limits.max_connections),
        ):
            if len(group) <= cap:
                continue
            idle = [c for c in group if c is not self and c._phase != RUNNING]
            victim = min(idle, key=lambda c: c._opened) if idle else self
            victim.transport.close()
            if victim is self:
                return


def server_config(app, limits: Limits = Limits(), **options) -> uvicorn.Config:
    """A uvicorn configuration serving ``app`` with `GuardedH11Protocol` under ``limits``; ``options`` are passed to
    `uvicorn.Config` (``log_level``, ``lifespan`` ...)."""
    protocol = type("GuardedH11", (GuardedH11Protocol,), {"limits": limits})
    return uvicorn.Config(
        app,
        http=protocol,
        timeout_keep_alive=limits.keep_alive_s,
        h11_max_incomplete_event_size=limits.max_header_bytes,
        **options,
    )

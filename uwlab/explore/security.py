"""Who may talk to the explorer, and how much: the guard in front of its web application (docs/explorer.md).

The explorer runs a model over files on the user's machine, so a request is served only when it could only have
come from the user, as Jupyter server does it:

- **Host allow-list** (DNS rebinding): the ``Host`` header must name the loopback (``localhost``, ``127.0.0.1``,
  ``::1``), the address the server listens on, or a name given with ``--allow-host``; anything else is 403.
- **Token**: with a token (always when listening on an address other than the loopback; ``--token`` otherwise),
  every request carries it: ``?token=`` on the page URL (then kept in an HttpOnly, SameSite=Strict cookie and
  removed from the address bar by a redirect), the cookie, or ``Authorization: token …``.
- **State-changing requests** (every ``POST``): ``Content-Type: application/json`` (a cross-origin page can send
  text/plain, form and multipart bodies without asking, never JSON); an ``Origin`` header, when present, equal to
  the server's own origin; a browser's request (one with ``Origin``) also carries the page's XSRF token — the
  ``_xsrf`` cookie repeated in the ``X-XSRF-Token`` header (double submit), which another origin cannot read. A
  client without ``Origin`` is not a browser: the token (when there is one) is its credential.
- **Limits**: a body over `MAX_BODY_BYTES` is refused (413) before it is read whole, and never echoed back.
- **Headers**: ``X-Content-Type-Options: nosniff``, a ``Content-Security-Policy`` allowing only the page's own
  scripts and styles, ``X-Frame-Options: DENY``, ``Referrer-Policy: no-referrer``; no CORS header, ever.

Refusals are JSON ``{"error": "<one line>"}`` with status 403, 413 or 415; they never repeat the request.
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import secrets
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from dataclasses import dataclass
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qsl, urlencode

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

MAX_BODY_BYTES = 1_000_000
TOKEN_COOKIE = "uwlab_token"
XSRF_COOKIE = "_xsrf"
XSRF_HEADER = "x-xsrf-token"
LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
SAFE_METHODS = frozenset({"GET", "HEAD"})
SECURITY_HEADERS = (
    (b"x-content-type-options", b"nosniff"),
    (
        b"content-security-policy",
        b"default-src 'none'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
        b"connect-src 'self'; font-src 'self' data:; base-uri 'none'; form-action 'self'; frame-ancestors 'none'",
    ),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"cache-control", b"no-store"),
)


def is_loopback(host: str) -> bool:
    """True for a loopback name or address (``localhost``, 127.0.0.0/8, ``::1``).

    >>> is_loopback("127.0.0.1"), is_loopback("localhost"), is_loopback("::1"), is_loopback("0.0.0.0")
    (True, True, True, False)
    """
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def host_name(header: str) -> str:
    """The host of a ``Host`` header, without its port, lower case (IPv6 without brackets).

    >>> host_name("LocalHost:8050"), host_name("[::1]:8050"), host_name("example.org")
    ('localhost', '::1', 'example.org')
    """
    header = header.strip().lower()
    if header.startswith("["):
        return header[1 : header.find("]")] if "]" in header else header[1:]
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


@dataclass(frozen=True)
class Access:
    """Who the explorer serves: the host names it answers to and its token (None: none needed)."""

    hosts: frozenset[str] = LOOPBACK_NAMES
    token: str | None = None
    max_body_bytes: int = MAX_BODY_BYTES

    @classmethod
    def for_server(cls, listen_host: str, allow_hosts: Iterable[str] = (), token: str | None = None) -> Access:
        """The access of a server listening on ``listen_host``: loopback names, that host and ``allow_hosts``; a
        server listening beyond the loopback always has a token (a new random one when none is given)."""
        hosts = set(LOOPBACK_NAMES) | {host_name(h) for h in allow_hosts}
        if listen_host not in ("0.0.0.0", "::", ""):
            hosts.add(host_name(listen_host) if not listen_host.startswith("[") else listen_host[1:-1].lower())
        if token is None and not is_loopback(listen_host):
            token = secrets.token_urlsafe(24)
        return cls(frozenset(hosts), token)


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}


def _cookies(headers: dict[str, str]) -> dict[str, str]:
    jar: SimpleCookie = SimpleCookie()
    try:
        jar.load(headers.get("cookie", ""))
    except Exception:  # a malformed Cookie header is no cookie
        return {}
    return {k: m.value for k, m in jar.items()}


def _same(a: str | None, b: str | None) -> bool:
    return a is not None and b is not None and hmac.compare_digest(a.encode(), b.encode())


class Guard:
    """ASGI middleware applying `Access` to every HTTP request (the module docstring)."""

    def __init__(self, app: ASGIApp, access: Access):
        self.app = app
        self.access = access

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        cookies = _cookies(headers)
        refusal = self._refusal(scope, headers, cookies)
        if refusal is not None:
            await _answer(send, *refusal)
            return
        query = dict(parse_qsl(scope.get("query_string", b"").decode("latin-1"), keep_blank_values=True))
        if self.access.token is not None and "token" in query and scope["method"] in SAFE_METHODS:
            await self._token_redirect(scope, query, send)
            return
        set_xsrf = XSRF_COOKIE not in cookies
        refused = False
        seen = 0

        async def send_guarded(message: Message) -> None:
            if refused:  # the body was cut: whatever the application answers after that is dropped
                return
            if message["type"] == "http.response.start":
                extra = list(SECURITY_HEADERS)
                if set_xsrf:
                    extra.append((b"set-cookie", _cookie(XSRF_COOKIE, secrets.token_urlsafe(32), http_only=False)))
                message["headers"] = [*message.get("headers", []), *extra]
            await send(message)

        async def receive_limited() -> Message:
            nonlocal refused, seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.access.max_body_bytes and not refused:
                    await _answer(send, 413, f"request body over {self.access.max_body_bytes} bytes")
                    refused = True
                    raise _TooLarge
            return message

        try:
            await self.app(scope, receive_limited, send_guarded)
        except _TooLarge:
            pass

    def _refusal(self, scope: Scope, headers: dict[str, str], cookies: dict[str, str]) -> tuple[int, str] | None:
        if host_name(headers.get("host", "")) not in self.access.hosts:
            return 403, "host not allowed (uwlab explore --allow-host NAME adds one)"
        if self.access.token is not None:
            query = dict(parse_qsl(scope.get("query_string", b"").decode("latin-1")))
            given = [query.get("token"), cookies.get(TOKEN_COOKIE)]
            auth = headers.get("authorization", "")
            if auth.lower().startswith("token "):
                given.append(auth[6:].strip())
            if not any(_same(g, self.access.token) for g in given):
                return 403, "a token is required: open the URL uwlab explore printed"
        if scope["method"] in SAFE_METHODS:
            return None
        origin = headers.get("origin")
        if origin is not None:
            own = f"{scope.get('scheme', 'http')}://{headers.get('host', '')}".lower()
            if origin.lower() != own:
                return 403, "cross-origin request refused"
            if not _same(headers.get(XSRF_HEADER), cookies.get(XSRF_COOKIE)):
                return 403, "XSRF token missing or wrong: reload the page"
        if headers.get("content-type", "").split(";")[0].strip().lower() != "application/json":
            return 415, "the API takes Content-Type: application/json"
        length = headers.get("content-length")
        if length is not None and (not length.isdigit() or int(length) > self.access.max_body_bytes):
            return 413, f"request body over {self.access.max_body_bytes} bytes"
        return None

    async def _token_redirect(self, scope: Scope, query: dict[str, str], send: Send) -> None:
        """Keep the token in a cookie and send the browser to the same address without it."""
        rest = urlencode({k: v for k, v in query.items() if k != "token"})
        location = scope.get("path", "/") + (f"?{rest}" if rest else "")
        await send(
            {
                "type": "http.response.start",
                "status": 303,
                "headers": [
                    (b"location", location.encode("latin-1")),
                    (b"set-cookie", _cookie(TOKEN_COOKIE, query["token"], http_only=True)),
                    *SECURITY_HEADERS,
                ],
            }
        )
        await send({"type": "http.response.body", "body": b""})


class _TooLarge(Exception):
    pass


def _cookie(name: str, value: str, http_only: bool) -> bytes:
    flags = "; Path=/; SameSite=Strict" + ("; HttpOnly" if http_only else "")
    return f"{name}={value}{flags}".encode("latin-1")


async def _answer(send: Send, status: int, message: str) -> None:
    body = json.dumps({"error": message}).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
                *SECURITY_HEADERS,
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})

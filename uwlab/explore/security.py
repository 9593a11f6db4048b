"""Who may talk to the explorer, and how much: the guard in front of its web application (docs/explorer.md).

The explorer runs a model over files on the user's machine, so a request is served only when it could only have
come from the user, as Jupyter server does it:

- **Host allow-list** (DNS rebinding): exactly one ``Host`` header, ``host[:port]`` as RFC 3986 §3.2.2–3.2.3 writes
  them (a registered name, an IPv4 address or a bracketed IPv6 address; a port of 1 to 5 digits, not empty), else
  400; the host must name the loopback (``localhost``, ``127.0.0.1``, ``::1``), the address the server listens on,
  or a name given with ``--allow-host``, else 403.
- **Token**: with a token (always when listening on an address other than the loopback; ``--token`` otherwise),
  every request carries it: ``?token=`` on the page URL (then kept in an HttpOnly, SameSite=Strict cookie and
  removed from the address bar by a redirect to a path on this server, never a ``//host`` reference), the cookie,
  or ``Authorization: token …``. A token is 8 to 256 characters of ``A-Z a-z 0-9 - . _ ~`` (`TOKEN`), and only
  the server's own token is ever written into a cookie.
- **State-changing requests** (every ``POST``): ``Content-Type: application/json`` (a cross-origin page can send
  text/plain, form and multipart bodies without asking, never JSON); an ``Origin`` header, when present, equal to
  the server's own origin; a browser's request (one with ``Origin``) also carries the page's XSRF token — the
  ``_xsrf`` cookie repeated in the ``X-XSRF-Token`` header (double submit), which another origin cannot read. A
  client without ``Origin`` is not a browser: the token (when there is one) is its credential.
- **Limits**: a body over `MAX_BODY_BYTES` is refused (413) before it is read whole, and never echoed back; a
  client that goes away before its body is whole ends the request quietly. Deadlines on receiving a request and
  caps on connections belong to the server below (`uwlab.explore.server`).
- **Headers**: ``X-Content-Type-Options: nosniff``, a ``Content-Security-Policy`` allowing only the page's own
  scripts and styles, ``X-Frame-Options: DENY``, ``Referrer-Policy: no-referrer``; no CORS header, ever.

Refusals are JSON ``{"error": "<one line>"}`` with status 400, 403, 413 or 415; they never repeat the request.
Nothing here knows what the application behind it is (the explorer; a rig console could use it as well).
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import re
import secrets
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from dataclasses import dataclass
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qsl, quote, urlencode

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
# A token and any cookie value the guard writes: URL-safe characters (RFC 3986 unreserved, RFC 6265 cookie-octet).
TOKEN = re.compile(r"[A-Za-z0-9\-._~]{8,256}")
# RFC 3986 §3.2.2 reg-name (unreserved, pct-encoded, sub-delims; IPv4 addresses are of this form too), §3.2.3 port.
_REG_NAME = re.compile(r"(?:[A-Za-z0-9\-._~!$&'()*+,;=]|%[0-9A-Fa-f]{2})*")
_PORT = re.compile(r":[0-9]{1,5}")
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


def host_name(header: str) -> str | None:
    """The host of a ``Host`` header (``host[:port]``, RFC 9110 §7.2 with RFC 3986 §3.2.2–3.2.3), lower case, an
    IPv6 address without its brackets, compressed; None when the header is not of that form (an empty port, which
    RFC 3986 allows but no client sends, is refused too).

    >>> host_name("LocalHost:8050"), host_name("[::1]:8050"), host_name("example.org")
    ('localhost', '::1', 'example.org')
    >>> [host_name(h) for h in ("127.0.0.1:8050.evil.com", "localhost:80@evil.com", "[localhost]:80", "localhost:")]
    [None, None, None, None]
    """
    if header.startswith("["):
        end = header.find("]")
        if end < 0:
            return None
        port = header[end + 1 :]
        try:
            host = str(ipaddress.IPv6Address(header[1:end]))
        except ValueError:
            return None
    else:
        host, colon, port = header.partition(":")
        port = colon + port
        if not _REG_NAME.fullmatch(host):
            return None
    return host.lower() if not port or _PORT.fullmatch(port) else None


def listen_name(address: str) -> str:
    """The name a listening address is reached by in a ``Host`` header (an IPv6 address without brackets).

    >>> listen_name("::1"), listen_name("[::1]"), listen_name("Lab-PC")
    ('::1', '::1', 'lab-pc')
    """
    try:
        return str(ipaddress.ip_address(address.strip("[]")))
    except ValueError:
        return address.lower()


@dataclass(frozen=True)
class Access:
    """Who the explorer serves: the host names it answers to and its token (None: none needed)."""

    hosts: frozenset[str] = LOOPBACK_NAMES
    token: str | None = None
    max_body_bytes: int = MAX_BODY_BYTES

    def __post_init__(self) -> None:
        if self.token is not None and not TOKEN.fullmatch(self.token):
            raise ValueError("a token is 8 to 256 characters of A-Z a-z 0-9 - . _ ~")

    @classmethod
    def for_server(cls, listen_host: str, allow_hosts: Iterable[str] = (), token: str | None = None) -> Access:
        """The access of a server listening on ``listen_host``: loopback names, that host and ``allow_hosts``; a
        server listening beyond the loopback always has a token (a new random one when none is given). An
        ``allow_hosts`` entry that `host_name` does not read is a `ValueError`."""
        hosts = set(LOOPBACK_NAMES)
        for given in allow_hosts:
            name = host_name(given)
            if name is None:
                raise ValueError(f"{given!r} is not a host name or address")
            hosts.add(name)
        if listen_host not in ("0.0.0.0", "::", ""):
            hosts.add(listen_name(listen_host))
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
        whole = False

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
            nonlocal refused, seen, whole
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                whole = not message.get("more_body", False)
                if seen > self.access.max_body_bytes and not refused:
                    await _answer(send, 413, f"request body over {self.access.max_body_bytes} bytes", close=True)
                    refused = True
                    raise _Cut
            elif message["type"] == "http.disconnect" and not whole:
                refused = True  # the client left (or the server cut it) before its body was whole: nobody to answer
                raise _Cut
            return message

        try:
            await self.app(scope, receive_limited, send_guarded)
        except _Cut:
            pass

    def _refusal(self, scope: Scope, headers: dict[str, str], cookies: dict[str, str]) -> tuple[int, str] | None:
        hosts = [v for k, v in scope.get("headers", []) if k.lower() == b"host"]
        host = host_name(hosts[0].decode("latin-1")) if len(hosts) == 1 else None
        if host is None:
            return 400, "a request needs one Host header: host[:port]"
        if host not in self.access.hosts:
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
        """Keep the token in a cookie (when it is the right one) and send the browser to the same path on this server
        without it: one leading ``/`` and no ``\\`` (a browser reads ``//host`` and ``/\\host`` as another host)."""
        raw = scope.get("raw_path") or quote(scope.get("path", "/")).encode("ascii")
        path = "/" + raw.decode("latin-1").lstrip("/\\").replace("\\", "%5C")
        rest = urlencode({k: v for k, v in query.items() if k != "token"})
        headers = [(b"location", (path + (f"?{rest}" if rest else "")).encode("latin-1"))]
        token = self.access.token
        if token is not None and _same(query["token"], token):
            headers.append((b"set-cookie", _cookie(TOKEN_COOKIE, token, http_only=True)))
        await send({"type": "http.response.start", "status": 303, "headers": [*headers, *SECURITY_HEADERS]})
        await send({"type": "http.response.body", "body": b""})


class _Cut(Exception):
    """The request's body was refused or its client left: the application's answer, if any, is dropped."""


def _cookie(name: str, value: str, http_only: bool) -> bytes:
    if not TOKEN.fullmatch(value):  # never: the values are the server's token and secrets.token_urlsafe(32)
        raise ValueError("a cookie value outside the token characters")
    flags = "; Path=/; SameSite=Strict" + ("; HttpOnly" if http_only else "")
    return f"{name}={value}{flags}".encode("latin-1")


async def _answer(send: Send, status: int, message: str, close: bool = False) -> None:
    """A refusal; ``close``: the connection closes after it (a body left unread is not waited for)."""
    body = json.dumps({"error": message}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    headers += [(b"connection", b"close")] if close else []
    await send({"type": "http.response.start", "status": status, "headers": [*headers, *SECURITY_HEADERS]})
    await send({"type": "http.response.body", "body": body})

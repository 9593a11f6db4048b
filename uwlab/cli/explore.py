"""`uwlab explore`: the design explorer, a local web page over a design (docs/explorer.md)."""

from __future__ import annotations

import asyncio
import json
import socket
import sys
import threading
import webbrowser
from pathlib import Path

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir

DEFAULT_PORT = 8050


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "explore",
        description="Serve the design explorer for a design TOML on a local address and open it in the browser.",
    )
    p.add_argument("config", nargs="?", help="design TOML (default: configs/design/example.toml)")
    add_server_arguments(p, DEFAULT_PORT, "the explorer")
    p.add_argument(
        "--data-dir",
        action="append",
        default=[],
        metavar="DIR",
        help="a folder whose files (spectra, transmittances, profiles) designs may name, besides configs/ "
        "and the config's folder (repeatable)",
    )
    p.add_argument(
        "--profile",
        action="append",
        default=[],
        metavar="PATH",
        help="a sensor (e.g. `uwlab emva` output), light or lens profile TOML, or a directory of them, "
        "offered beside the shipped ones (repeatable)",
    )
    p.set_defaults(func=run)


def add_server_arguments(p, default_port: int, what: str) -> None:
    """The options of a web verb (the explorer, the console): where it listens, who may reach it, how it starts."""
    p.add_argument(
        "--port", type=int, default=default_port, help=f"TCP port (default {default_port}; 0: any free port)"
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1; any other address requires a token, printed in the URL)",
    )
    p.add_argument(
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help=f"a host name the browser may use to reach {what} besides the loopback names and --host "
        "(repeatable; other Host headers are refused, against DNS rebinding)",
    )
    p.add_argument(
        "--token",
        metavar="TOKEN",
        help="require this token (default: none on the loopback, a new random one on any other address)",
    )
    p.add_argument("--no-browser", action="store_true", help="do not open a browser")
    p.add_argument("--json", action="store_true", help='print {"url": ...} as one JSON line')


def listening(args):
    """(access, listening socket, URL to print) of a web verb's options (`add_server_arguments`), each checked
    first: one line naming the option."""
    from uwlab.explore.security import TOKEN, Access, host_name

    if args.token is not None and not TOKEN.fullmatch(args.token):
        raise ConfigError("--token", args.token, "must be 8 to 256 characters of A-Z a-z 0-9 - . _ ~")
    for name in args.allow_host:
        if host_name(name) is None:
            raise ConfigError("--allow-host", name, "not a host name or address (RFC 3986)")
    access = Access.for_server(args.host, args.allow_host, args.token)
    sock = _listen(args.host, args.port)
    host, port = sock.getsockname()[:2]
    url = f"http://{_reachable(host)}:{port}/" + (f"?token={access.token}" if access.token else "")
    return access, sock, url


def _listen(host: str, port: int) -> socket.socket:
    """A listening socket on host:port, or a one-line error naming the option."""
    if not 0 <= port <= 65535:
        raise ConfigError("--port", port, "must be in [0, 65535]")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ConfigError("--host", host, f"not an address ({exc.strerror})") from None
    family, _, _, _, address = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
    except OSError as exc:
        sock.close()
        key, value = ("--port", port) if exc.errno in (98, 13) else ("--host", host)
        raise ConfigError(key, value, f"cannot listen on {host}:{port} ({exc.strerror})") from None
    sock.listen(128)
    return sock


def serve_until_stopped(server, sock: socket.socket, url: str, line: str, args) -> None:
    """Serve on ``sock`` and, once the server accepts connections, print ``line`` (``--json``: ``{"url": ...}``)
    and open a browser unless ``--no-browser``; returns when the server stops (uvicorn handles Ctrl-C itself). The
    explorer's and the console's one way of starting."""

    async def serve() -> None:
        task = asyncio.ensure_future(server.serve(sockets=[sock]))
        while not server.started and not task.done():
            await asyncio.sleep(0.01)
        if server.started:
            if args.json:
                json.dump({"url": url}, sys.stdout)
                sys.stdout.write("\n")
            else:
                print(line)
            sys.stdout.flush()
            if not args.no_browser:
                threading.Timer(0.5, webbrowser.open, (url,)).start()
        await task

    asyncio.run(serve())


def _reachable(host: str) -> str:
    """The host of the printed URL: a wildcard address (any interface) is not one a browser may ask for, its
    loopback is (and is always allowed, `uwlab.explore.security`); an IPv6 address in brackets."""
    host = {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(host, host)
    return f"[{host}]" if ":" in host else host


def run(args) -> int:
    import uvicorn

    from uwlab.explore.app import create_app
    from uwlab.explore.catalog import Catalog
    from uwlab.explore.inputs import load_served
    from uwlab.explore.security import is_loopback
    from uwlab.explore.server import server_config

    served = load_served(args.config or config_dir() / "design" / "example.toml")
    catalog = Catalog()
    for path in args.profile:
        catalog.add_profiles(path)
    for folder in args.data_dir:
        if not Path(folder).expanduser().is_dir():
            raise ConfigError("--data-dir", folder, "not a directory")
    served = served.with_roots(*args.profile, *args.data_dir)
    access, sock, url = listening(args)
    if not is_loopback(args.host):
        print(
            f"uwlab explore: warning: listening on {args.host}, beyond this machine; anyone who can reach it "
            "and has the token can run designs and read the files of --data-dir",
            file=sys.stderr,
        )
    server = uvicorn.Server(
        server_config(create_app(served, catalog, access), log_level="warning", access_log=False, lifespan="off")
    )

    serve_until_stopped(server, sock, url, f"uwlab explore: {served.path} at {url} (Ctrl-C stops)", args)
    return 0

"""`uwlab explore`: the design explorer, a local web page over a design (docs/explorer.md)."""

from __future__ import annotations

import asyncio
import json
import socket
import sys
import threading
import webbrowser

from uwlab.errors import ConfigError
from uwlab.model.data import config_dir

DEFAULT_PORT = 8050


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "explore",
        description="Serve the design explorer for a design TOML on a local address and open it in the browser.",
    )
    p.add_argument("config", nargs="?", help="design TOML (default: configs/design/example.toml)")
    p.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0: any free port)"
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1; the explorer serves anyone who can reach it)",
    )
    p.add_argument(
        "--profile",
        action="append",
        default=[],
        metavar="PATH",
        help="a sensor (e.g. `uwlab emva` output), light or lens profile TOML, or a directory of them, "
        "offered beside the shipped ones (repeatable)",
    )
    p.add_argument("--no-browser", action="store_true", help="do not open a browser")
    p.add_argument("--json", action="store_true", help='print {"url": ...} as one JSON line')
    p.set_defaults(func=run)


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


def run(args) -> int:
    import uvicorn

    from uwlab.explore.app import create_app
    from uwlab.explore.catalog import Catalog
    from uwlab.explore.inputs import load_served

    served = load_served(args.config or config_dir() / "design" / "example.toml")
    catalog = Catalog()
    for path in args.profile:
        catalog.add_profiles(path)
    sock = _listen(args.host, args.port)
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{port}/"
    server = uvicorn.Server(
        uvicorn.Config(create_app(served, catalog), log_level="warning", access_log=False, lifespan="off")
    )

    async def serve() -> None:
        """Serve, and print the URL once the server accepts connections (and handles Ctrl-C itself)."""
        task = asyncio.ensure_future(server.serve(sockets=[sock]))
        while not server.started and not task.done():
            await asyncio.sleep(0.01)
        if server.started:
            if args.json:
                json.dump({"url": url}, sys.stdout)
                sys.stdout.write("\n")
            else:
                print(f"uwlab explore: {served.path} at {url} (Ctrl-C stops)")
            sys.stdout.flush()
            if not args.no_browser:
                threading.Timer(0.5, webbrowser.open, (url,)).start()
        await task

    asyncio.run(serve())
    return 0

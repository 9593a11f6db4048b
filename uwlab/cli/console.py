"""`uwlab console`: the rig console, a local web page to see and steer the rig live (docs/console.md)."""

from __future__ import annotations

import sys

from uwlab.cli.explore import add_server_arguments
from uwlab.errors import ConfigError
from uwlab.model.data import config_dir

DEFAULT_PORT = 8060


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "console",
        description="Serve the rig console: the live image with its histogram, clipped pixels and sharpness, the "
        "camera's settings, the lights and the spectrometer, and sweep runs with pause, resume and abort.",
    )
    p.add_argument(
        "rig",
        nargs="?",
        metavar="RIG.toml",
        help="a rig file (simulated, with --sim; default configs/rigs/sim-tank.toml) or a sweep plan naming the "
        "tank's camera, lights and spectrometer",
    )
    p.add_argument("--sim", action="store_true", help="serve the simulated rig (camera, light, spectrometer)")
    add_server_arguments(p, DEFAULT_PORT, "the console")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated rig's noise (runs: as uwlab sweep)")
    p.add_argument("--max-fps", type=float, default=12.0, help="most frames a second the live view grabs")
    p.set_defaults(func=run)


def run(args) -> int:
    import uvicorn

    from uwlab.cli.explore import listening, serve_until_stopped
    from uwlab.explore.console import create_console
    from uwlab.explore.console_rig import Live, Runs, Source
    from uwlab.explore.security import is_loopback
    from uwlab.explore.server import server_config

    if args.rig is None and not args.sim:
        raise ConfigError("RIG.toml", None, "give the plan naming the rig's devices, or --sim")
    if not 0 < args.max_fps <= 100:
        raise ConfigError("--max-fps", args.max_fps, "must be in (0, 100]")
    source = Source(args.rig or config_dir() / "rigs" / "sim-tank.toml", args.sim, args.seed)
    access, sock, url = listening(args)
    if not is_loopback(args.host):
        print(
            f"uwlab console: warning: listening on {args.host}, beyond this machine; anyone who can reach it and "
            "has the token can steer the rig",
            file=sys.stderr,
        )
    live = Live(source, max_fps=args.max_fps)
    runs = Runs(live, sim=args.sim, seed=args.seed)
    live.start()
    try:
        # The explorer's server: its header and body read deadlines and connection caps (`uwlab.explore.server`).
        server = uvicorn.Server(
            server_config(
                create_console(live, runs, access),
                log_level="warning",
                access_log=False,
                lifespan="off",
                timeout_graceful_shutdown=1,
            )
        )

        simulated = "(simulated) " if args.sim else ""
        serve_until_stopped(server, sock, url, f"uwlab console: {source.path} {simulated}at {url} (Ctrl-C stops)", args)
    finally:
        try:
            runs.close()
        finally:
            live.close()
    return 0

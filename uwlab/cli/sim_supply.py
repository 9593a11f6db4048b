"""`uwlab sim supply`: a simulated CV/CC supply (or LED driver) with an LED load, on TCP or a pseudo-terminal."""

from __future__ import annotations

import signal
import threading
from contextlib import ExitStack

from uwlab.errors import ConfigError, DeviceError
from uwlab.model.schema import Seed, check
from uwlab.sim.devices.led_load import LOAD_FAULTS
from uwlab.sim.devices.supply import DIALECTS, SupplyTwin, serve


def add_sim_supply_parser(sub) -> None:
    p = sub.add_parser(
        "supply",
        help="simulated programmable supply with an LED load (SCPI over TCP or a pty)",
        description="Serve a simulated CV/CC supply (or the DC2200 LED driver) driving a white power LED, "
        "answering SCPI as the chosen instrument's manual says; print its VISA resource on one line "
        "(open it with pyvisa-py: --visa-library @py, read termination \\n); run until SIGTERM (exit 0) "
        "or Ctrl-C (exit 130).",
    )
    p.add_argument("--dialect", choices=DIALECTS, default="scpi", help="which instrument to be (default: scpi)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--tcp",
        type=int,
        metavar="PORT",
        default=0,
        help="raw SCPI on 127.0.0.1:PORT (5025 as LXI instruments; default 0: any free port)",
    )
    where.add_argument("--pty", action="store_true", help="a serial line on a pseudo-terminal (ASRL/dev/pts/N::INSTR)")
    p.add_argument("--fault", choices=LOAD_FAULTS, help="start with the LED open or shorted")
    p.add_argument("--idn", help="the *IDN? answer (four comma-separated fields; default: the dialect's model)")
    p.add_argument("--seed", type=int, default=0, help="seed of the measurement noise")
    p.set_defaults(func=run_sim_supply)


def run_sim_supply(args) -> int:
    if not 0 <= args.tcp <= 65535:
        raise ConfigError("tcp", args.tcp, "a TCP port is 0-65535 (0: any free port)")
    seed = check(Seed, args.seed, "seed")
    try:
        twin = SupplyTwin(args.dialect, idn=args.idn, seed=seed)
    except ValueError as exc:
        raise ConfigError("idn", args.idn, str(exc)) from None
    twin.set_fault(args.fault)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    where = "a pseudo-terminal" if args.pty else f"127.0.0.1:{args.tcp}"
    try:
        with ExitStack() as stack:
            try:
                resource = stack.enter_context(serve(twin, "pty" if args.pty else "tcp", args.tcp))
            except OSError as exc:
                raise DeviceError(f"cannot serve the simulated supply on {where}: {exc.strerror or exc}") from None
            print(resource, flush=True)
            while not stop.wait(0.5):
                continue
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0

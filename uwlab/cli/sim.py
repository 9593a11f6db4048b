"""`uwlab sim`: run simulated instruments (one function pair per sub-subcommand)."""

from __future__ import annotations

import json
import signal
import sys
import tempfile
import threading
import time

from uwlab.cli.sim_camera import add_sim_camera_parser
from uwlab.cli.sim_charuco import add_sim_charuco_parser
from uwlab.cli.sim_supply import add_sim_supply_parser
from uwlab.model.evaluation import SPECTROMETER_POSITIONS
from uwlab.sim.devices.serial_sim import SerialRig, SerialSimSettings
from uwlab.errors import DeviceError

RESTARTS_ALLOWED = 3
RESTART_WINDOW_S = 60.0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sim",
        description="Run simulated instruments that behave like the rig's hardware, or "
        "render image sets with the simulated camera.",
    )
    sub = p.add_subparsers(dest="sim_command", required=True, metavar="INSTRUMENTS")
    register_serial(sub)
    add_sim_camera_parser(sub)
    add_sim_charuco_parser(sub)
    add_sim_supply_parser(sub)


def register_serial(sub) -> None:
    p = sub.add_parser(
        "serial",
        help="simulated light and spectrometer on pseudo-terminals",
        description="Start the simulated light and spectrometer behind pseudo-terminals, print "
        "their ports, and run until SIGTERM (exit 0) or Ctrl-C (exit 130). A simulator "
        "that dies is restarted at its power-on state (one line on stderr), like an "
        f"instrument power-cycled; more than {RESTARTS_ALLOWED} deaths of one simulator "
        f"within {RESTART_WINDOW_S:g} s stop the command with exit code 2.",
    )
    p.add_argument("--config", metavar="RIG.toml", help="rig config (default: configs/rigs/sim-tank.toml)")
    p.add_argument(
        "--spectrometer-position",
        choices=SPECTROMETER_POSITIONS,
        default="target",
        help="where the spectrometer sits: facing the light at the target board, or at the camera",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help='print {"light": PORT, "spectrometer": PORT, "rig_state": FILE} as the first line',
    )
    p.set_defaults(func=run_serial)


def run_serial(args) -> int:
    settings = SerialSimSettings.from_config(args.config, args.spectrometer_position)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with tempfile.TemporaryDirectory(prefix="uwlab-sim-") as directory, SerialRig(directory, settings) as rig:
            info = {**rig.ports, "rig_state": str(rig.rig_state_path)}
            if args.json:
                print(json.dumps(info), flush=True)
            else:
                print(
                    f"light:        {info['light']}\nspectrometer: {info['spectrometer']}\n"
                    f"rig state:    {info['rig_state']}\nrunning; Ctrl-C to stop",
                    flush=True,
                )
            _serve(rig, stop)
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0


def _serve(rig: SerialRig, stop: threading.Event) -> None:
    """Until ``stop``: restart any simulator that died; a crash loop is a `DeviceError`."""
    deaths: dict[str, list[float]] = {}
    while not stop.wait(0.5):
        for name, code in rig.revive().items():
            now = time.monotonic()
            recent = [t for t in deaths.get(name, []) if now - t < RESTART_WINDOW_S] + [now]
            deaths[name] = recent
            if len(recent) > RESTARTS_ALLOWED:
                raise DeviceError(
                    f"the {name} simulator died {len(recent)} times within "
                    f"{RESTART_WINDOW_S:g} s (last exit code {code}); stopping"
                )
            print(
                f"uwlab sim serial: the {name} simulator died (exit code {code}); restarted at its "
                f"power-on state on {rig.ports[name]}",
                file=sys.stderr,
                flush=True,
            )

"""`uwlab sim camera --gige`: serve the simulated camera over GigE Vision on a loopback address."""

from __future__ import annotations

import ipaddress
import json
import os
import signal
import threading

from uwlab.sim.devices.camera import sensor_from_rig
from uwlab.sim.devices.gige import GVCP_PORT, GigeCameraServer, GigeFaults
from uwlab.errors import ConfigError
from uwlab.model.data import MAX_JSON_BYTES, check_input_file
from uwlab.model.schema import Seed, check

LOOPBACK = ipaddress.IPv4Network("127.0.0.0/8")


def add_sim_camera_parser(sub) -> None:
    p = sub.add_parser(
        "camera",
        help="simulated GigE Vision camera on 127.0.0.1",
        description="Serve the simulated camera (EMVA 1288 physics of the rig) over GigE Vision; "
        "print its address and device id once ready; run until SIGTERM (exit 0) or Ctrl-C "
        "(exit 130).",
    )
    p.add_argument("--gige", action="store_true", required=True, help="serve over GigE Vision (GVCP/GVSP)")
    p.add_argument("--config", metavar="RIG.toml", help="rig config (default: configs/rigs/sim-tank.toml)")
    p.add_argument(
        "--address", default="127.0.0.1", help="loopback IPv4 address to serve on (127.x.y.z), one camera per address"
    )
    p.add_argument("--rig-state", metavar="FILE", help="light-state file shared with `uwlab sim serial`")
    p.add_argument("--seed", type=int, default=0, help="seed of the fixed patterns and noise")
    p.add_argument(
        "--incomplete-every",
        type=int,
        default=0,
        metavar="N",
        help="fault injection: lose one packet of every N-th frame for good",
    )
    p.add_argument(
        "--stray-every",
        type=int,
        default=0,
        metavar="N",
        help="fault injection: before every N-th frame, a stray packet opening a block no host can make a frame of",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help='print {"address", "gvcp_port", "gvsp_port", "device_id"} as one JSON line once ready',
    )
    p.set_defaults(func=run_sim_camera)


def loopback_address(text: str) -> str:
    """`text` as a dotted-quad loopback IPv4 address, or a `ConfigError` naming it."""
    try:
        address = ipaddress.IPv4Address(text)
    except ValueError:
        raise ConfigError("address", text, "not an IPv4 address (expected 127.x.y.z)") from None
    if address not in LOOPBACK:
        raise ConfigError("address", text, "the simulated camera serves on loopback addresses only (127.x.y.z)")
    return str(address)


def run_sim_camera(args) -> int:
    address = loopback_address(args.address)
    for flag, value in (("incomplete-every", args.incomplete_every), ("stray-every", args.stray_every)):
        if value < 0:
            raise ConfigError(flag, value, "must be >= 0")
    check(Seed, args.seed, "--seed")
    if args.rig_state is not None and os.path.lexists(args.rig_state):  # a mistake shown now, not a dark image later
        check_input_file(args.rig_state, "--rig-state", MAX_JSON_BYTES, "light-state")
    sensor = sensor_from_rig(args.config, args.seed, rig_state=args.rig_state)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with GigeCameraServer(sensor, address, faults=GigeFaults(args.incomplete_every, args.stray_every)) as server:
            info = {
                "address": server.address,
                "gvcp_port": GVCP_PORT,
                "gvsp_port": server.stream_port,
                "device_id": server.device_id,
            }
            if args.json:
                print(json.dumps(info), flush=True)
            else:
                print(
                    f"GigE Vision camera {info['device_id']}\naddress:   {info['address']} (GVCP port "
                    f"{info['gvcp_port']}, GVSP from port {info['gvsp_port']})\nrunning; Ctrl-C to stop",
                    flush=True,
                )
            while not stop.wait(0.5):
                continue
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0

"""`uwlab sim camera --gige`: serve the simulated camera over GigE Vision on a loopback address."""
from __future__ import annotations

import json
import signal
import threading

from uwlab.drivers.sim.camera import sensor_from_rig
from uwlab.drivers.sim.gige import GigeCameraServer, GigeFaults
from uwlab.errors import ConfigError


def add_sim_camera_parser(sub) -> None:
    p = sub.add_parser("camera", help="simulated GigE Vision camera on 127.0.0.1",
                       description="Serve the simulated camera (EMVA 1288 physics of the rig) over GigE Vision; "
                                   'print {"address": ..., "device_id": ...} once ready; run until Ctrl-C or SIGTERM.')
    p.add_argument("--gige", action="store_true", required=True, help="serve over GigE Vision (GVCP/GVSP)")
    p.add_argument("--config", metavar="RIG.toml", help="rig config (default: configs/rigs/sim-tank.toml)")
    p.add_argument("--address", default="127.0.0.1", help="loopback IPv4 address to serve on (127.x.y.z)")
    p.add_argument("--rig-state", metavar="FILE", help="light-state file shared with `uwlab sim serial`")
    p.add_argument("--seed", type=int, default=0, help="seed of the fixed patterns and noise")
    p.add_argument("--incomplete-every", type=int, default=0, metavar="N",
                   help="fault injection: lose one packet of every N-th frame for good")
    p.set_defaults(func=run_sim_camera)


def run_sim_camera(args) -> int:
    if not args.address.startswith("127."):
        raise ConfigError("address", args.address, "the simulated camera serves on loopback addresses only (127.x.y.z)")
    sensor = sensor_from_rig(args.config, args.seed, rig_state=args.rig_state)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with GigeCameraServer(sensor, args.address, faults=GigeFaults(args.incomplete_every)) as server:
            print(json.dumps({"address": server.address, "device_id": server.device_id}), flush=True)
            try:
                while not stop.wait(0.5):
                    continue
            except KeyboardInterrupt:
                stop.set()
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0

"""`uwlab light`: switch and dim the light; `uwlab light calibrate`: its level → irradiance curve."""

from __future__ import annotations

import json
from datetime import datetime, UTC

from uwlab.progress import bar

from uwlab.drivers.serial import PROTOCOLS, open_light, open_spectrometer
from uwlab.drivers.serial.base import check_level
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.light_calibration import calibrate_light, calibration_levels, save_light_calibration
from uwlab.outputs import output_file

DEFAULT_CALIBRATION = "light-calibration.csv"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "light",
        description="Set and read back the light: a uwlab-ascii controller on a serial port (--port), or any "
        "instrument with a definition in configs/instruments/ on a VISA resource (--instrument, --resource).",
    )
    p.add_argument("--port", help="serial port of the light (e.g. /dev/ttyUSB0)")
    p.add_argument("--instrument", metavar="NAME|FILE", help="instrument definition (configs/instruments/NAME.toml)")
    p.add_argument("--resource", metavar="RESOURCE", help="VISA resource of --instrument (e.g. USB0::...::INSTR)")
    p.add_argument(
        "--visa-library",
        metavar="LIB",
        help="PyVISA library: @py (default, pure Python), PATH.yaml@sim (pyvisa-sim), or a vendor VISA's path",
    )
    p.add_argument("--protocol", choices=PROTOCOLS, default=PROTOCOLS[0], help="instrument protocol")
    output = p.add_mutually_exclusive_group()
    output.add_argument("--on", dest="output", action="store_const", const=True, help="switch the output on")
    output.add_argument("--off", dest="output", action="store_const", const=False, help="switch the output off")
    p.add_argument("--level", type=float, help="light level in [0, 1]")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)
    sub = p.add_subparsers(dest="light_command", metavar="calibrate")
    c = sub.add_parser(
        "calibrate",
        help="measure irradiance at N light levels",
        description="Step the light through N levels in [0, 1] and store the spectrum at each.",
    )
    c.add_argument("--light", required=True, metavar="PORT", help="serial port of the light")
    c.add_argument("--spectrometer", required=True, metavar="PORT", help="serial port of the spectrometer")
    c.add_argument("--protocol", choices=PROTOCOLS, default=PROTOCOLS[0], help="instrument protocol")
    c.add_argument("--levels", type=int, default=11, help="number of levels, evenly spaced over [0, 1] (default 11)")
    c.add_argument(
        "--out",
        default=DEFAULT_CALIBRATION,
        metavar="FILE",
        help=f"calibration CSV to create; never overwritten (default {DEFAULT_CALIBRATION})",
    )
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_calibrate)


def run(args) -> int:
    if args.instrument is not None:
        return run_instrument(args)
    if args.resource is not None or args.visa_library is not None:
        raise ConfigError("resource", args.resource or args.visa_library, "needs --instrument")
    if args.port is None:
        raise ConfigError("port", None, "--port or --instrument is required (or use 'uwlab light calibrate')")
    if args.level is not None:
        check_level(args.level)
    with open_light(args.port, args.protocol) as light:
        if args.output is not None:
            light.set_output(args.output)
        if args.level is not None:
            light.set_level(args.level)
        state = {"port": args.port, "identity": light.identity(), "on": light.output(), "level": light.level()}
    if args.json:
        print(json.dumps(state))
    else:
        print(f"{state['identity']} on {args.port}: output {'on' if state['on'] else 'off'}, level {state['level']:g}")
    return 0


def run_instrument(args) -> int:
    """``--instrument NAME --resource RESOURCE``: set, then print the read-back (on, level, drive, measured)."""
    from uwlab.drivers.instruments import open_light_instrument

    if args.port is not None:
        raise ConfigError("port", args.port, "give either --port or --instrument")
    if args.resource is None:
        raise ConfigError("resource", None, "--instrument needs --resource (uwlab devices lists them)")
    if args.level is not None:
        check_level(args.level)
    with open_light_instrument(args.instrument, args.resource, args.visa_library) as light:
        if args.level is not None:
            light.set_level(args.level)
        if args.output is not None:
            light.set_output(args.output)
        state = {
            "instrument": args.instrument,
            "resource": args.resource,
            "identity": light.identity(),
            **light.state(),
        }
        light.keep_output = True
    if args.json:
        print(json.dumps(state))
    else:
        print(f"{state['identity']} on {args.resource}: " + ", ".join(f"{k} {v}" for k, v in list(state.items())[3:]))
    return 0


def run_calibrate(args) -> int:
    levels = calibration_levels(args.levels)
    out = output_file(args.out, "--out")
    with (
        open_light(args.light, args.protocol) as light,
        open_spectrometer(args.spectrometer, args.protocol) as spectrometer,
        bar(total=len(levels), desc="light levels", unit="level") as shown,
    ):
        comments = [
            f"uwlab light calibration, {datetime.now(UTC).isoformat(timespec='seconds')}",
            f"light: {args.light} ({light.identity()})",
            f"spectrometer: {args.spectrometer} ({spectrometer.identity()})",
        ]
        calibration = calibrate_light(light, spectrometer, levels, lambda done, total: shown.update(1))
    save_light_calibration(out, calibration, comments)
    result = {
        "out": str(out),
        "level": calibration.level.tolist(),
        "irradiance_w_m2": calibration.irradiance_w_m2.tolist(),
        "illuminance_lux": calibration.illuminance_lux.tolist(),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"light calibration written to {out}")
        print(f"{'level':>8} {'irradiance_w_m2':>16} {'illuminance_lux':>16}")
        for row in zip(result["level"], result["irradiance_w_m2"], result["illuminance_lux"], strict=True):
            print(f"{row[0]:8.3f} {row[1]:16.6g} {row[2]:16.6g}")
    return 0

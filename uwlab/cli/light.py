"""`uwlab light`: switch and dim the light; `uwlab light calibrate`: its level → irradiance curve."""

from __future__ import annotations

import json
from datetime import datetime, UTC

from uwlab.progress import bar

from uwlab.api.instruments import open_light, open_spectrometer
from uwlab.drivers.instruments.definition import LightRig, MaxCurrentA, VoltageV, load_light_definition, load_light_rig
from uwlab.drivers.instruments.discovery import check_visa_library
from uwlab.drivers.ocean_insight import read_dark
from uwlab.drivers.serial import PROTOCOLS
from uwlab.drivers.serial.base import check_integration_ms, check_level
from uwlab.errors import ConfigError
from uwlab.experiments.acquisition.light_calibration import calibrate_light, calibration_levels, save_light_calibration
from uwlab.model.schema import check
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
    p.add_argument("--level", type=float, help="light level in [0, 1] (of --max-current-a)")
    p.add_argument(
        "--max-current-a",
        type=float,
        metavar="A",
        help="the LED's rated current: level 1; above it refused before anything is sent (default: the definition's)",
    )
    p.add_argument(
        "--forward-voltage-v",
        type=float,
        metavar="V",
        help="the LED's maximum forward voltage: a supply's voltage limit is this plus the definition's margin",
    )
    p.add_argument(
        "--rig",
        metavar="FILE.toml",
        help="the light's rig file: max_current_a, forward_voltage_v, identity_contains (the options override it)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)
    sub = p.add_subparsers(dest="light_command", metavar="calibrate")
    c = sub.add_parser(
        "calibrate",
        help="measure irradiance at N light levels",
        description="Step the light through N levels in [0, 1] and store the spectrum at each.",
    )
    light = c.add_argument_group("the light (one of)")
    light.add_argument("--light", metavar="PORT", help="serial port of a uwlab-ascii light")
    light.add_argument(
        "--instrument", metavar="NAME|FILE", help="light by instrument definition (configs/instruments/)"
    )
    light.add_argument("--resource", metavar="RESOURCE", help="VISA resource (or serial port) of --instrument")
    light.add_argument("--visa-library", metavar="LIB", help="PyVISA library: @py (default), PATH.yaml@sim, a vendor's")
    light.add_argument(
        "--max-current-a", type=float, help="the rig's maximum drive [A]: full level (default: the definition's)"
    )
    light.add_argument(
        "--forward-voltage-v", type=float, help="the LED's maximum forward voltage [V]: a supply's voltage limit"
    )
    spectrometer = c.add_argument_group("the spectrometer (one of)")
    spectrometer.add_argument("--spectrometer", metavar="PORT", help="serial port of a uwlab-ascii spectrometer")
    spectrometer.add_argument(
        "--spectrometer-instrument",
        metavar="NAME",
        help="spectrometer by instrument definition (ocean-insight: python-seabreeze; docs/spectrometers.md)",
    )
    spectrometer.add_argument(
        "--spectrometer-resource", metavar="SERIAL", help="its serial number (default: the first)"
    )
    spectrometer.add_argument(
        "--calibration", metavar="FILE.csv", help="its irradiance calibration (wavelength_nm, uJ_per_count)"
    )
    spectrometer.add_argument("--area-cm2", type=float, help="its collection area [cm²] (default: the definition's)")
    spectrometer.add_argument(
        "--dark", metavar="FILE.csv", help="a dark spectrum (default: the device's electric dark)"
    )
    spectrometer.add_argument("--integration-ms", type=float, help="its integration time [ms] (halved while saturated)")
    c.add_argument("--protocol", choices=PROTOCOLS, default=PROTOCOLS[0], help="protocol of --light/--spectrometer")
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
    extra = next((k for k in ("max_current_a", "forward_voltage_v", "rig") if getattr(args, k) is not None), None)
    if extra is not None:
        raise ConfigError(extra.replace("_", "-"), getattr(args, extra), "needs --instrument (a supply's definition)")
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
    if args.port is not None:
        raise ConfigError("port", args.port, "give either --port or --instrument")
    _require_resource(args)
    if args.level is not None:
        check_level(args.level)
    rig = _light_rig(args)
    with open_light(
        args.resource,
        instrument=args.instrument,
        visa_library=args.visa_library,
        max_current_a=rig.max_current_a,
        forward_voltage_v=rig.forward_voltage_v,
        identity_contains=tuple(rig.identity_contains),
    ) as light:
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
    """The light by port or definition, the spectrometer by port or definition; every input is checked before
    either is opened, and the light goes to its safe state on any exit."""
    levels = calibration_levels(args.levels)
    out = output_file(args.out, "--out")
    light_options, light_name = _calibration_light(args)
    spectrometer_options, spectrometer_name = _calibration_spectrometer(args)
    dark = None if args.dark is None else read_dark(args.dark)
    with (
        open_spectrometer(**spectrometer_options) as spectrometer,  # first: its files are checked on opening
        open_light(**light_options) as light,
        bar(total=len(levels), desc="light levels", unit="level") as shown,
    ):
        if dark is not None:
            spectrometer.use_dark(dark, args.dark)
        comments = [
            f"uwlab light calibration, {datetime.now(UTC).isoformat(timespec='seconds')}",
            f"light: {light_name} ({light.identity()})",
            f"spectrometer: {spectrometer_name} ({spectrometer.identity()})",
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


def _light_rig(args) -> LightRig:
    """The light's rig (`LightRig`): ``--rig FILE`` with ``--max-current-a`` (the lower of the two rules) and
    ``--forward-voltage-v`` over it, each checked against its plausible range before anything is opened."""
    rig = LightRig() if args.rig is None else load_light_rig(args.rig)
    limit = check(MaxCurrentA, args.max_current_a, "max-current-a") if args.max_current_a is not None else None
    given = args.forward_voltage_v
    forward = check(VoltageV, given, "forward-voltage-v") if given is not None else None
    limits = [v for v in (rig.max_current_a, limit) if v is not None]
    return rig.model_copy(
        update={
            "max_current_a": min(limits) if limits else None,
            "forward_voltage_v": forward if forward is not None else rig.forward_voltage_v,
        }
    )


def _require_resource(args) -> None:
    """--instrument names a definition; the device it drives is --resource."""
    if args.resource is None:
        raise ConfigError("resource", None, "--instrument needs --resource (uwlab devices lists them)")


def _calibration_light(args) -> tuple[dict, str]:
    """`uwlab.open_light`'s arguments and the light's name in the file, from --light or --instrument."""
    if (args.light is None) == (args.instrument is None):
        raise ConfigError("light", args.light or args.instrument, "give either --light PORT or --instrument NAME")
    if args.light is not None:
        keys = ("resource", "visa_library", "max_current_a", "forward_voltage_v")
        extra = next((k for k in keys if getattr(args, k) is not None), None)
        if extra is not None:
            raise ConfigError(extra.replace("_", "-"), getattr(args, extra), "needs --instrument (not --light)")
        return {"port": args.light, "protocol": args.protocol}, args.light
    _require_resource(args)
    load_light_definition(args.instrument)  # its files checked before the spectrometer is opened
    check_visa_library(args.visa_library)
    options = {
        "port": args.resource,
        "instrument": args.instrument,
        "visa_library": args.visa_library,
        "max_current_a": args.max_current_a,
        "forward_voltage_v": args.forward_voltage_v,
    }
    return options, f"{args.instrument} on {args.resource}"


def _calibration_spectrometer(args) -> tuple[dict, str]:
    """`uwlab.open_spectrometer`'s arguments and the spectrometer's name in the file."""
    if (args.spectrometer is None) == (args.spectrometer_instrument is None):
        raise ConfigError(
            "spectrometer",
            args.spectrometer or args.spectrometer_instrument,
            "give either --spectrometer PORT or --spectrometer-instrument NAME",
        )
    if args.spectrometer is not None:
        keys = ("spectrometer_resource", "calibration", "area_cm2", "dark", "integration_ms")
        extra = next((k for k in keys if getattr(args, k) is not None), None)
        if extra is not None:
            raise ConfigError(extra.replace("_", "-"), getattr(args, extra), "needs --spectrometer-instrument")
        return {"port": args.spectrometer, "protocol": args.protocol}, args.spectrometer
    if args.integration_ms is not None:
        check_integration_ms(args.integration_ms)
    options = {
        "port": args.spectrometer_resource,
        "instrument": args.spectrometer_instrument,
        "calibration": args.calibration,
        "area_cm2": args.area_cm2,
        "integration_ms": args.integration_ms,
        "dark_mode": "electric" if args.dark is None else "measured",
    }
    where = args.spectrometer_resource or "the first found"
    return options, f"{args.spectrometer_instrument} {where}, calibration {args.calibration}"

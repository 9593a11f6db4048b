"""`uwlab devices`: cameras found on every backend (sim, harvesters, aravis), VISA resources (with ``*IDN?`` where
they answer) and serial ports, one line each."""

from __future__ import annotations

import json
import sys

from uwlab.drivers.camera import discover
from uwlab.errors import said


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "devices",
        description="List cameras from every available backend, VISA resources (with *IDN? where they answer) and "
        "serial ports; missing backends are reported.",
    )
    p.add_argument(
        "--cti",
        action="append",
        default=[],
        metavar="PATH",
        help="GenTL producer for harvesters (repeatable; default: GENICAM_GENTL64_PATH)",
    )
    p.add_argument(
        "--fake",
        action="store_true",
        help="also list the test cameras shipped with the backends: "
        "Aravis's fake camera (Fake_1) and the genicam package's GenTL test producer (harvesters)",
    )
    p.add_argument("--config", metavar="RIG.toml", help="rig of the simulated camera (default rig if omitted)")
    p.add_argument(
        "--visa-library",
        metavar="LIB",
        help="PyVISA library to list VISA resources with: @py (default, pure Python), PATH.yaml@sim (pyvisa-sim), "
        "or a vendor VISA's path",
    )
    p.add_argument("--json", action="store_true", help="print one JSON list of {backend, id, vendor, model, serial}")
    p.set_defaults(func=run)


def run(args) -> int:
    found, unavailable = discover(cti=args.cti, config=args.config, fake=args.fake)
    instruments, missing = _instruments(args.visa_library)
    for backend, reason in {**unavailable, **missing}.items():
        print(f"uwlab devices: {backend} backend unavailable: {reason}", file=sys.stderr)
    if args.json:
        print(json.dumps([d.to_dict() for d in [*found, *instruments]]))
        return 0
    for d in found:
        print(f"{d.backend:<11} {d.id:<32} {d.vendor} {d.model} (serial {d.serial})")
    if not found:
        print("no cameras found")
    for i in instruments:
        said = " ".join(part for part in (i.vendor, i.model) if part)
        said = said or ("(no *IDN? answer)" if i.backend == "visa" else "serial port")
        print(f"{i.backend:<11} {i.id:<32} {said}" + (f" (serial {i.serial})" if i.serial else ""))
    return 0


def _instruments(visa_library: str | None) -> tuple[list, dict[str, str]]:
    """VISA resources and serial ports, and the reason a backend could not be listed."""
    from uwlab.drivers.instruments.discovery import serial_ports, visa_resources

    found, missing = [], {}
    try:
        found += visa_resources(visa_library)
    except Exception as exc:  # a VISA library that does not load: reported, the rest still listed
        missing["visa"] = f"{visa_library or '@py'}: {said(exc)}"
    try:
        found += serial_ports()
    except Exception as exc:
        missing["serial"] = said(exc)
    return found, missing

"""`uwlab devices`: cameras found on every backend (sim, harvesters, aravis)."""

from __future__ import annotations

import json
import sys

from uwlab.drivers.camera import discover


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "devices", description="List cameras from every available backend; missing backends are reported."
    )
    p.add_argument(
        "--cti",
        action="append",
        default=[],
        metavar="PATH",
        help="GenTL producer for harvesters (repeatable; default: GENICAM_GENTL64_PATH)",
    )
    p.add_argument("--config", metavar="RIG.toml", help="rig of the simulated camera (default rig if omitted)")
    p.add_argument("--json", action="store_true", help="print one JSON list of {backend, id, vendor, model, serial}")
    p.set_defaults(func=run)


def run(args) -> int:
    found, unavailable = discover(cti=args.cti, config=args.config)
    for backend, reason in unavailable.items():
        print(f"uwlab devices: {backend} backend unavailable: {reason}", file=sys.stderr)
    if args.json:
        print(json.dumps([d.to_dict() for d in found]))
        return 0
    for d in found:
        print(f"{d.backend:<11} {d.id:<32} {d.vendor} {d.model} (serial {d.serial})")
    if not found:
        print("no cameras found")
    return 0

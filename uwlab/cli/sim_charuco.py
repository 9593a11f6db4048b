"""`uwlab sim charuco`: ChArUco images seen by the simulated camera through the design's port, with true poses."""

from __future__ import annotations

import sys

from uwlab.jsonable import dumps


def add_sim_charuco_parser(sub) -> None:
    p = sub.add_parser(
        "charuco",
        help="render ChArUco board images through the port (PNG + true poses)",
        description="Render a ChArUco board seen by the simulated camera through the design's port "
        "(exact refraction), in air or in water, at seeded random poses; write "
        "pose-NNN.png and charuco.json (board, camera, port and the true poses) to DIR.",
    )
    p.add_argument("config", help="design TOML (sensor, lens, housing), e.g. configs/design/dome-8mm.toml")
    p.add_argument("--medium", choices=("air", "water"), required=True, help="what is outside the port")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one value, e.g. housing.dome_decenter_mm=1,0,-2",
    )
    p.add_argument("--poses", type=int, default=10, metavar="N", help="number of images (default 10)")
    p.add_argument("--out", required=True, metavar="DIR", help="new (or empty) folder for the images")
    p.add_argument("--board", metavar="FILE", help="board TOML (default configs/boards/charuco-7x5-40mm.toml)")
    p.add_argument("--seed", type=int, default=0, help="seed of the poses and the sensor noise")
    p.add_argument(
        "--downsample", type=int, default=4, metavar="N", help="render at 1/N of the sensor's resolution (default 4)"
    )
    p.add_argument("--lens-k1", type=float, default=0.0, metavar="K1", help="radial distortion k1 of the lens")
    p.add_argument("--json", action="store_true", help="print the sidecar record as JSON")
    p.set_defaults(func=run_sim_charuco)


def run_sim_charuco(args) -> int:
    from uwlab.cli.port import overrides
    from uwlab.experiments.port.board import CharucoBoard
    from uwlab.experiments.port.simulate import SIDECAR, simulate_charuco
    from uwlab.model.design import load_design

    design = load_design(args.config, overrides(args.set))
    board = CharucoBoard.from_toml(args.board)
    record = simulate_charuco(
        design, board, args.medium, args.poses, args.out, seed=args.seed, downsample=args.downsample, k1=args.lens_k1
    )
    if args.json:
        sys.stdout.write(dumps(record, indent=2) + "\n")
    else:
        width, height = record["camera"]["resolution_px"]
        print(f"{len(record['poses'])} images ({width}x{height} px, {args.medium}) and {SIDECAR} written to {args.out}")
    return 0

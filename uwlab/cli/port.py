"""`uwlab port`: exact port optics of a design (`trace`) and the port's calibration from ChArUco images
(`calibrate`)."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from uwlab.errors import ConfigError
from uwlab.jsonable import dumps
from uwlab.model.config import parse_value, split_assignment

if TYPE_CHECKING:
    from uwlab.experiments.port.calibrate import PortCalibration


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "port",
        description="Trace a design's housing port exactly, or calibrate a port from ChArUco "
        "images taken in air and in water.",
    )
    sub = p.add_subparsers(dest="port_command", required=True, metavar="ACTION")
    t = sub.add_parser(
        "trace",
        help="exact FOV, distortion, virtual images and focusing aids of a design's port",
        description="Ray-trace the design's port (Snell's law, exact): field of view, the distortion "
        "it adds, the virtual image of the target plane across the field, the paraxial "
        "rule's error, and where to focus.",
    )
    t.add_argument("config", help="design TOML (see configs/design/dome-8mm.toml)")
    t.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one value")
    t.add_argument("--plot", metavar="DIR", help="write port_distortion.png and port_focus.png to DIR")
    t.add_argument("--json", action="store_true", help="print one JSON object")
    t.set_defaults(func=run_trace)

    c = sub.add_parser(
        "calibrate",
        help="calibrate the port from ChArUco images in air and in water",
        description="Detect ChArUco corners, calibrate the lens in air (OpenCV), then fit the port "
        "(dome decentring, or flat-port distance and tilt) and f_uw/f_air by minimising "
        "the reprojection error through the exact ray tracing. "
        "See docs/port-calibration.md.",
    )
    c.add_argument("air", metavar="DIR_AIR", help="images of the board in air, housing closed")
    c.add_argument("water", metavar="DIR_WATER", help="images of the board in water")
    c.add_argument("--port", choices=("flat", "dome"), required=True, help="the port model to fit")
    c.add_argument(
        "--config",
        required=True,
        metavar="DESIGN.toml",
        help="design whose [housing] gives the port's nominal geometry and indices",
    )
    c.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one value")
    c.add_argument("--board", metavar="FILE", help="board TOML (default configs/boards/charuco-7x5-40mm.toml)")
    c.add_argument(
        "--focus",
        choices=("locked", "refocused"),
        default="locked",
        help="locked (default): the lens was not touched between the two sets; refocused: fit its "
        "focal length in water too",
    )
    c.add_argument(
        "--max-distortion-px",
        type=float,
        default=None,
        metavar="PX",
        help="a dome is centred enough when its decentring adds at most this distortion (default 0.5)",
    )
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_calibrate)

    b = sub.add_parser(
        "board",
        help="write the ChArUco board as a PNG to print",
        description="Write the board (with its white margin) as a PNG at the given resolution, with "
        "the DPI recorded so that it prints at 100 %% scale.",
    )
    b.add_argument("--board", metavar="FILE", help="board TOML (default configs/boards/charuco-7x5-40mm.toml)")
    b.add_argument("--dpi", type=int, default=300, help="print resolution (default 300)")
    b.add_argument("--out", required=True, metavar="FILE.png", help="new PNG file")
    b.add_argument("--json", action="store_true", help='print {"path", "size_mm", "dpi", "board"}')
    b.set_defaults(func=run_board)


def overrides(items: list[str]) -> dict:
    """`--set SECTION.KEY=VALUE` arguments as {"section.key": value}."""
    return {key: parse_value(value) for key, value in (split_assignment(item, "--set") for item in items)}


def _trace_table(result: dict) -> str:
    aid = result["focus"]
    rows = [
        ("port", result["port"], ""),
        ("field of view, exact (x, y)", f"{result['fov_deg']['x']:.2f}, {result['fov_deg']['y']:.2f}", "deg"),
        (
            "field of view, paraxial (x, y)",
            f"{result['paraxial_fov_deg']['x']:.2f}, {result['paraxial_fov_deg']['y']:.2f}",
            "deg",
        ),
        (
            "focal ratio f_uw/f (exact, paraxial)",
            f"{result['focal_ratio']:.4f}, {result['paraxial_focal_ratio']:.4f}",
            "",
        ),
        (
            "distortion added (edge, corner)",
            f"{result['distortion_percent']['edge']:+.3f}, {result['distortion_percent']['corner']:+.3f}",
            "%",
        ),
        (
            "distortion added (edge, corner)",
            f"{result['distortion_px']['edge']:+.2f}, {result['distortion_px']['corner']:+.2f}",
            "px",
        ),
        (
            "paraxial rule error (edge, corner)",
            f"{result['paraxial_error_deg']['edge']:+.4f}, {result['paraxial_error_deg']['corner']:+.4f}",
            "deg",
        ),
        (
            "paraxial rule error (edge, corner)",
            f"{result['paraxial_error_px']['edge']:+.2f}, {result['paraxial_error_px']['corner']:+.2f}",
            "px",
        ),
        (
            "virtual image (on axis, edge)",
            f"{result['virtual_image_m']['on_axis']:.4f}, {result['virtual_image_m']['edge']:.4f}",
            "m",
        ),
        ("lens focus setting", f"{aid['setting_m']:.4f}", "m"),
        (
            "close-up lens needed",
            "n/a" if aid["close_up_lens_dpt"] is None else f"{aid['close_up_lens_dpt']:.2f}",
            "dpt",
        ),
        (
            "depth of field in water (near, far)",
            f"{aid['dof_m']['near']:.3f}, "
            + ("inf" if aid["dof_m"]["far"] == float("inf") else f"{aid['dof_m']['far']:.3f}"),
            "m",
        ),
        (
            "in focus when focused on axis (edge, corner)",
            f"{str(aid['edge_in_focus']).lower()}, {str(aid['corner_in_focus']).lower()}",
            "",
        ),
    ]
    return "\n".join(f"{label:<46} {value} {unit}".rstrip() for label, value, unit in rows)


def run_trace(args) -> int:
    from uwlab.model.build import load_design
    from uwlab.model.port_field import trace_design
    from uwlab.outputs import output_dir

    plot_dir = output_dir(args.plot, "--plot") if args.plot else None
    design = load_design(args.config, overrides(args.set))
    result = trace_design(design)
    written = []
    if plot_dir is not None:
        from uwlab.experiments.port.plots import write_trace_plots

        plot_dir.mkdir(exist_ok=True)
        written = write_trace_plots(design, result, plot_dir)
    summary = {k: v for k, v in result.items() if k != "profile"}
    if args.json:
        sys.stdout.write(dumps(summary, indent=2) + "\n")
    else:
        print(_trace_table(summary))
        if written:
            print(f"plots: {', '.join(str(p) for p in written)}")
    return 0


def _calibration_table(result: PortCalibration) -> str:
    def pm(value, std, fmt="{:+.3f}"):
        return f"{fmt.format(value)} ± {std:.3f}"

    rows = [("port", result["port"], "")]
    if result["port"] == "dome":
        for axis in "xyz":
            rows.append((f"decentring {axis}", pm(result["decenter_mm"][axis], result["decenter_mm_std"][axis]), "mm"))
    else:
        rows.append(
            (
                "port distance (pupil → inner face)",
                pm(result["port_distance_mm"], result["port_distance_mm_std"], "{:.3f}"),
                "mm",
            )
        )
        for axis in "xy":
            rows.append((f"tilt about {axis}", pm(result["tilt_deg"][axis], result["tilt_deg_std"][axis]), "deg"))
    rows.append(("f_uw / f_air", f"{result['f_ratio']:.5f} ± {result['f_ratio_std']:.5f}", ""))
    rows.append(("RMS reprojection error (water, air)", f"{result['rms_px']:.3f}, {result['air']['rms_px']:.3f}", "px"))
    rows.append(
        (
            "views used (water, air)",
            f"{result['water']['views']} of {result['water']['images']}, "
            f"{result['air']['views']} of {result['air']['images']}",
            "",
        )
    )
    if result["port"] == "dome":
        verdict = "yes" if result["centred_enough"] else "NO"
        rows.append(("distortion added by the decentring", f"{result['induced_distortion_px']:.2f}", "px"))
        rows.append((f"centred enough (≤ {result['max_distortion_px']:g} px)", verdict, ""))
    return "\n".join(f"{label:<38} {value} {unit}".rstrip() for label, value, unit in rows)


def run_calibrate(args) -> int:
    from uwlab.experiments.port.board import CharucoBoard
    from uwlab.experiments.port.calibrate import DEFAULT_MAX_DISTORTION_PX, calibrate_port
    from uwlab.model.build import load_design
    from uwlab.model.port_field import port_of

    design = load_design(args.config, {"housing.port": args.port, **overrides(args.set)})
    limit = DEFAULT_MAX_DISTORTION_PX if args.max_distortion_px is None else args.max_distortion_px
    if not limit > 0:
        raise ConfigError("--max-distortion-px", limit, "must be > 0")
    result = calibrate_port(
        CharucoBoard.from_toml(args.board),
        args.air,
        args.water,
        args.port,
        port_of(design),
        refocused=args.focus == "refocused",
        max_distortion_px=limit,
    )
    if args.json:
        sys.stdout.write(dumps(result, indent=2) + "\n")
    else:
        print(_calibration_table(result))
    return 0


def run_board(args) -> int:
    from uwlab.experiments.port.board import CharucoBoard, write_printable

    board = CharucoBoard.from_toml(args.board)
    path = write_printable(board, args.out, args.dpi)
    width, height = (round(s * 1e3) for s in board.printed_size_m)
    if args.json:
        record = {"path": path, "size_mm": [width, height], "dpi": args.dpi, "board": board.to_dict()}
        sys.stdout.write(dumps(record) + "\n")
    else:
        print(f"{path}: {width} mm × {height} mm at {args.dpi} dpi (print at 100 % scale, then measure a square)")
    return 0

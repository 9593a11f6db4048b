"""`uwlab port`: exact port optics of a design (`trace`) and the port's calibration from ChArUco images
(`calibrate`)."""
from __future__ import annotations

import sys

from uwlab.jsonable import dumps
from uwlab.model.config import parse_value, split_assignment


def register(subparsers) -> None:
    p = subparsers.add_parser("port", help="exact port optics and focusing aids; port calibration from images",
                              description="Trace a design's housing port exactly, or calibrate a port from ChArUco "
                                          "images taken in air and in water.")
    sub = p.add_subparsers(dest="port_command", required=True, metavar="ACTION")
    t = sub.add_parser("trace", help="exact FOV, distortion, virtual images and focusing aids of a design's port",
                       description="Ray-trace the design's port (Snell's law, exact): field of view, the distortion "
                                   "it adds, the virtual image of the target plane across the field, the paraxial "
                                   "rule's error, and where to focus.")
    t.add_argument("config", help="design TOML (see configs/design/dome-8mm.toml)")
    t.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one value")
    t.add_argument("--plot", metavar="DIR", help="write port_distortion.png and port_focus.png to DIR")
    t.add_argument("--json", action="store_true", help="print one JSON object")
    t.set_defaults(func=run_trace)


def overrides(items: list[str]) -> dict:
    """`--set SECTION.KEY=VALUE` arguments as {"section.key": value}."""
    return {key: parse_value(value) for key, value in (split_assignment(item, "--set") for item in items)}


def _trace_table(result: dict) -> str:
    aid = result["focus"]
    rows = [
        ("port", result["port"], ""),
        ("field of view, exact (x, y)", f"{result['fov_deg']['x']:.2f}, {result['fov_deg']['y']:.2f}", "deg"),
        ("field of view, paraxial (x, y)",
         f"{result['paraxial_fov_deg']['x']:.2f}, {result['paraxial_fov_deg']['y']:.2f}", "deg"),
        ("focal ratio f_uw/f (exact, paraxial)", f"{result['focal_ratio']:.4f}, {result['paraxial_focal_ratio']:.4f}", ""),
        ("distortion added (edge, corner)",
         f"{result['distortion_percent']['edge']:+.3f}, {result['distortion_percent']['corner']:+.3f}", "%"),
        ("distortion added (edge, corner)",
         f"{result['distortion_px']['edge']:+.2f}, {result['distortion_px']['corner']:+.2f}", "px"),
        ("paraxial rule error (edge, corner)",
         f"{result['paraxial_error_deg']['edge']:+.4f}, {result['paraxial_error_deg']['corner']:+.4f}", "deg"),
        ("paraxial rule error (edge, corner)",
         f"{result['paraxial_error_px']['edge']:+.2f}, {result['paraxial_error_px']['corner']:+.2f}", "px"),
        ("virtual image (on axis, edge)",
         f"{result['virtual_image_m']['on_axis']:.4f}, {result['virtual_image_m']['edge']:.4f}", "m"),
        ("lens focus setting", f"{aid['setting_m']:.4f}", "m"),
        ("close-up lens needed", "n/a" if aid["close_up_lens_dpt"] is None else f"{aid['close_up_lens_dpt']:.2f}", "dpt"),
        ("depth of field in water (near, far)", f"{aid['dof_m']['near']:.3f}, "
         + ("inf" if aid["dof_m"]["far"] == float("inf") else f"{aid['dof_m']['far']:.3f}"), "m"),
        ("edge in focus", str(aid["edge_in_focus"]).lower(), ""),
    ]
    return "\n".join(f"{label:<38} {value} {unit}".rstrip() for label, value, unit in rows)


def run_trace(args) -> int:
    from uwlab.experiments.port.files import output_dir
    from uwlab.model.design import load_design
    from uwlab.model.port_field import trace_design

    design = load_design(args.config, overrides(args.set))
    result = trace_design(design)
    written = []
    if args.plot:
        from uwlab.experiments.port.plots import write_trace_plots

        written = write_trace_plots(design, result, output_dir(args.plot, "--plot"))
    summary = {k: v for k, v in result.items() if k != "profile"}
    if args.json:
        sys.stdout.write(dumps(summary, indent=2) + "\n")
    else:
        print(_trace_table(summary))
        if written:
            print(f"plots: {', '.join(str(p) for p in written)}")
    return 0

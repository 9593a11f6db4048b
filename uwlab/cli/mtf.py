"""`uwlab mtf IMAGE`: the slanted-edge MTF (ISO 12233 e-SFR) of the edges in an image (`experiments.frames.esfr`)."""

from __future__ import annotations

import json

from uwlab.drivers.camera.pixels import BAYER_LAYOUTS
from uwlab.experiments.frames.esfr import CHANNELS, measure_image


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "mtf",
        description="Measure the MTF of each slanted edge in an image (ISO 12233:2017 e-SFR): the edge angle, MTF50 "
        "and the MTF at Nyquist in cycles per pixel, and the curve. TIFF or PNG, 8 or 16 bit, monochrome, RGB or a "
        "raw Bayer mosaic (--bayer).",
    )
    p.add_argument("image", metavar="IMAGE", help="TIFF or PNG, 8 or 16 bit")
    p.add_argument("--roi", metavar="X,Y,W,H", help="the region holding one edge (default: every edge found)")
    p.add_argument(
        "--channel",
        choices=CHANNELS,
        help="colour channel: a plane of an RGB image, or the sites of a raw Bayer mosaic given with --bayer "
        "(default: an RGB image's luminance, every pixel of a mosaic or monochrome image)",
    )
    p.add_argument("--bayer", choices=BAYER_LAYOUTS, help="the image is a raw Bayer mosaic of this layout")
    p.add_argument("--json", action="store_true", help="print a JSON list, one object per edge")
    p.set_defaults(func=run)


def run(args) -> int:
    edges = measure_image(args.image, roi=args.roi, channel=args.channel, bayer=args.bayer)
    if args.json:
        print(json.dumps([edge.to_json() for edge in edges]))
        return 0
    print(f"{'roi (x, y, w, h)':<24}{'angle':>8}{'MTF50':>10}{'MTF@Nyq':>10}")
    for edge in edges:
        roi = ",".join(str(v) for v in edge.roi)
        print(f"{roi:<24}{edge.angle_deg:>7.2f}°{edge.mtf50_cy_per_px:>10.4f}{edge.mtf_nyquist:>10.3f}")
    print("MTF50 in cycles per pixel (Nyquist 0.5), along the edge normal")
    return 0

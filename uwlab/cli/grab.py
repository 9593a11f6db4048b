"""`uwlab grab`: acquire frames from one camera and report per-frame statistics."""

from __future__ import annotations

import json

from uwlab.drivers.camera import BACKENDS
from uwlab.drivers.camera.pixels import BAYER_LAYOUTS, MONO_FORMATS


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "grab",
        description="Acquire N frames; report mean, std, min, max and saturated "
        "fraction per frame (and per colour channel R, G, B of a raw "
        "Bayer frame).",
    )
    p.add_argument(
        "--backend", choices=tuple(BACKENDS), help="camera backend (default: sim; with --fake, aravis's Fake_1)"
    )
    p.add_argument("--device", metavar="ID", help="device id (aravis: id or IP address); default: first found")
    p.add_argument("--cti", action="append", default=[], metavar="PATH", help="GenTL producer (harvesters)")
    p.add_argument(
        "--fake",
        action="store_true",
        help="the backend's test camera: Aravis's Fake_1 (the default "
        "device for aravis), the genicam package's GenTL test producer (harvesters, besides --cti)",
    )
    p.add_argument("--config", metavar="RIG.toml", help="rig of the simulated camera")
    p.add_argument(
        "--sensor",
        metavar="PROFILE",
        help="sensor profile (name or TOML) giving the clip level of "
        "saturated pixels (default for --backend sim: the rig's; else detected from the frames)",
    )
    p.add_argument("--exposure-us", type=float)
    p.add_argument("--gain-db", type=float)
    p.add_argument(
        "--pixel-format",
        metavar="F",
        help=f"PFNC name: {', '.join(MONO_FORMATS)}, Bayer{{RG,GR,GB,BG}}{{8,10,12,16,10p,12p,10Packed,12Packed}}",
    )
    p.add_argument(
        "--bayer",
        choices=BAYER_LAYOUTS,
        help="the colour filter layout the camera must deliver "
        "(refused when its PixelFormat is another layout or monochrome)",
    )
    p.add_argument("--frames", type=int, default=1)
    p.add_argument("--roi", metavar="x,y,w,h", help="device region of interest in pixels")
    p.add_argument("--timeout-s", type=float, default=5.0, help="per-frame acquisition timeout")
    p.add_argument(
        "--save",
        metavar="DIR",
        help="write each frame as TIFF with its settings in the metadata (DIR is created if its parent exists)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object {device, frames}")
    p.set_defaults(func=run)


def run(args) -> int:
    from uwlab.experiments.acquisition.grab import Settings, grab_frames, parse_roi

    settings = Settings(
        exposure_us=args.exposure_us,
        gain_db=args.gain_db,
        pixel_format=args.pixel_format,
        roi=parse_roi(args.roi) if args.roi else None,
        bayer=args.bayer,
    )
    grabbed = grab_frames(
        args.backend,
        args.device,
        frames=args.frames,
        settings=settings,
        sensor=args.sensor,
        config=args.config,
        cti=args.cti,
        fake=args.fake,
        timeout_s=args.timeout_s,
        keep_frames=False,
        save_dir=args.save,
    )
    device, rows = grabbed.device, grabbed.rows
    if args.json:
        print(json.dumps({"device": device, "frames": rows}))
        return 0
    print(f"{device['backend']}:{device['device_id']} {device['vendor']} {device['model']} (serial {device['serial']})")
    for r in rows:
        print(
            f"frame {r['frame_id']}: {r['width']}x{r['height']} {r['pixel_format']} exposure {r['exposure_us']} us "
            f"gain {r['gain_db']} dB  mean {r['mean']:.2f} std {r['std']:.2f} min {r['min']} max {r['max']} "
            f"saturated {100 * r['saturated_fraction']:.3f} % (clip {r['clip_level_dn']:g} DN, {r['clip_source']})"
        )
        for colour, c in (r["channels"] or {}).items():
            print(f"  {colour}: mean {c['mean']:.2f} saturated {100 * c['saturated_fraction']:.3f} %")
    return 0

"""`uwlab grab`: acquire frames from one camera and report per-frame statistics."""

from __future__ import annotations

import json
from pathlib import Path

from uwlab.drivers.camera import BACKENDS, Camera, Frame, Policy, open_camera
from uwlab.errors import ConfigError
from uwlab.experiments.saturation import clip_level, sensor_clip_dn
from uwlab.model.sensor import SensorProfile, load_sensor_profile
from uwlab.outputs import output_dir


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "grab", description="Acquire N frames; report mean, std, min, max and saturated fraction per frame."
    )
    p.add_argument("--backend", choices=tuple(BACKENDS), default="sim")
    p.add_argument("--device", metavar="ID", help="device id (aravis: id or IP address); default: first found")
    p.add_argument("--cti", action="append", default=[], metavar="PATH", help="GenTL producer (harvesters)")
    p.add_argument("--config", metavar="RIG.toml", help="rig of the simulated camera")
    p.add_argument(
        "--sensor",
        metavar="PROFILE",
        help="sensor profile (name or TOML) giving the clip level of "
        "saturated pixels (default for --backend sim: the rig's; else detected from the frames)",
    )
    p.add_argument("--exposure-us", type=float)
    p.add_argument("--gain-db", type=float)
    p.add_argument("--pixel-format", metavar="F", help="Mono8, Mono10, Mono10p, Mono12, Mono12p, Mono12Packed, Mono16")
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


def parse_roi(text: str) -> tuple[int, int, int, int]:
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise ConfigError("roi", text, "expected four integers x,y,w,h") from None
    if min(x, y) < 0 or min(w, h) < 1:
        raise ConfigError("roi", text, "offsets must be >= 0 and sizes >= 1")
    return x, y, w, h


def frame_stats(frame: Frame, sensor: SensorProfile | None) -> dict:
    """Statistics of one frame; saturated pixels by the one rule (`uwlab.experiments.saturation`)."""
    img = frame.image
    s = frame.settings
    profile_dn = None
    if sensor is not None:
        offset = sensor.dark_offset_dn + (s.black_level or 0.0)
        profile_dn = sensor_clip_dn(
            sensor.gain_k(s.gain_db or 0.0), sensor.saturation_e, offset, sensor.bit_depth, frame.pixel_format
        )
    clip = clip_level(
        frame.pixel_format, native_bits=sensor.bit_depth if sensor else None, profile_dn=profile_dn, image=img
    )
    return {
        "frame_id": frame.frame_id,
        "timestamp_ns": frame.timestamp_ns,
        "width": int(img.shape[1]),
        "height": int(img.shape[0]),
        "pixel_format": frame.pixel_format,
        "exposure_us": s.exposure_us,
        "gain_db": s.gain_db,
        "mean": float(img.mean()),
        "std": float(img.std()),
        "min": int(img.min()),
        "max": int(img.max()),
        "saturated_fraction": clip.fraction(img),
        "clip_level_dn": clip.dn,
        "clip_source": clip.source,
    }


def apply_settings(cam: Camera, args) -> None:
    if args.pixel_format:
        cam.pixel_format = args.pixel_format
    if args.roi:
        cam.set_roi(*parse_roi(args.roi))
    if args.exposure_us is not None:
        cam.exposure_us = args.exposure_us
    if args.gain_db is not None:
        cam.gain_db = args.gain_db


def unique_path(directory: Path, stem: str) -> Path:
    """A new file name in ``directory``: existing files are never overwritten."""
    candidate, n = directory / f"{stem}.tiff", 1
    while candidate.exists():
        candidate, n = directory / f"{stem}-{n}.tiff", n + 1
    return candidate


def save_tiff(directory: Path, frame: Frame, device: dict) -> Path:
    import tifffile

    metadata = {
        "device": device,
        "frame_id": frame.frame_id,
        "timestamp_ns": frame.timestamp_ns,
        "pixel_format": frame.pixel_format,
        "settings": frame.settings.to_dict(),
    }
    while True:
        path = unique_path(directory, f"frame-{frame.frame_id:06d}")
        try:
            with open(path, "xb") as fh:
                tifffile.imwrite(fh, frame.image, metadata=metadata)
            return path
        except FileExistsError:
            continue


def run(args) -> int:
    from uwlab.model.schema import ExposureUs, GainDb, check

    if args.frames < 1:
        raise ConfigError("frames", args.frames, "must be >= 1")
    if args.exposure_us is not None:
        check(ExposureUs, args.exposure_us, "--exposure-us")
    if args.gain_db is not None:
        check(GainDb, args.gain_db, "--gain-db")
    save_dir = output_dir(args.save, "--save") if args.save else None
    options = {"cti": args.cti} if args.backend == "harvesters" else {}
    sensor = load_sensor_profile(args.sensor) if args.sensor else None
    if args.backend == "sim":
        options["config"] = args.config
        if sensor is None:
            from uwlab.sim.scene import RigScene

            sensor = RigScene.from_toml(args.config).sensor
    with open_camera(args.backend, args.device, policy=Policy(timeout_s=args.timeout_s), **options) as cam:
        apply_settings(cam, args)
        device = {k: v for k, v in vars(cam.info).items()}
        if save_dir is not None:
            save_dir.mkdir(exist_ok=True)
        rows = []
        for frame in cam.stream(args.frames):
            rows.append(frame_stats(frame, sensor))
            if save_dir is not None:
                save_tiff(save_dir, frame, device)
        device["discarded_frames"] = cam.stats.discarded
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
    return 0

"""Grabbing frames from one camera with statistics per frame — what `uwlab grab` and `uwlab.grab` run.

Each frame's statistics: size, pixel format, the settings read back with it, mean, standard deviation, minimum,
maximum and the fraction of saturated pixels by the one rule of `uwlab.experiments.saturation` (the clip level from
the sensor profile when one is known, else from the pixel format and the image).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from uwlab.drivers.camera import Camera, Frame, Policy, open_camera
from uwlab.errors import ConfigError
from uwlab.experiments.saturation import clip_level, sensor_clip_dn
from uwlab.model.sensor import SensorProfile, load_sensor_profile


def parse_roi(text: str) -> tuple[int, int, int, int]:
    """``"x,y,w,h"`` → (x, y, w, h), offsets ≥ 0 and sizes ≥ 1.

    >>> parse_roi("0,8,64,32")
    (0, 8, 64, 32)
    """
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise ConfigError("roi", text, "expected four integers x,y,w,h") from None
    if min(x, y) < 0 or min(w, h) < 1:
        raise ConfigError("roi", text, "offsets must be >= 0 and sizes >= 1")
    return x, y, w, h


def frame_stats(frame: Frame, sensor: SensorProfile | None) -> dict[str, Any]:
    """Statistics of one frame (module docstring)."""
    img = frame.image
    s = frame.settings
    profile_dn = None
    if sensor is not None:
        offset = sensor.dark_offset_dn + (s.black_level or 0.0)
        gain: float = sensor.gain_k(s.gain_db or 0.0)  # type: ignore[no-untyped-call]  # model not yet typed
        profile_dn = sensor_clip_dn(gain, sensor.saturation_e, offset, sensor.bit_depth, frame.pixel_format)
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


@dataclass(frozen=True)
class Settings:
    """Camera settings to apply before grabbing (None: leave as the camera has it)."""

    exposure_us: float | None = None
    gain_db: float | None = None
    pixel_format: str | None = None
    roi: tuple[int, int, int, int] | None = None

    def check(self) -> None:
        """Plausibility limits (`uwlab.model.schema`) before anything is sent to a camera."""
        from uwlab.model.schema import ExposureUs, GainDb, check

        if self.exposure_us is not None:
            check(ExposureUs, self.exposure_us, "--exposure-us")
        if self.gain_db is not None:
            check(GainDb, self.gain_db, "--gain-db")

    def apply(self, cam: Camera) -> None:
        """Write the settings (the camera reads each back and refuses a value it did not take)."""
        if self.pixel_format:
            cam.pixel_format = self.pixel_format
        if self.roi:
            cam.set_roi(*self.roi)
        if self.exposure_us is not None:
            cam.exposure_us = self.exposure_us
        if self.gain_db is not None:
            cam.gain_db = self.gain_db


@dataclass
class Grabbed:
    """What `grab_frames` returns: the device (its `CameraInfo` fields and ``discarded_frames``), the frames and a
    statistics row per frame."""

    device: dict[str, Any]
    frames: list[Frame] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list)


def sensor_for(backend: str, sensor: str | None, config: str | None) -> SensorProfile | None:
    """The sensor profile giving the clip level: `sensor` (a name or TOML), else for the simulated camera its
    rig's, else None (the clip level is then detected from the frames)."""
    if sensor is not None:
        return load_sensor_profile(sensor)
    if backend == "sim":
        from uwlab.sim.scene import RigScene

        return RigScene.from_toml(config).sensor
    return None


def grab_frames(
    backend: str = "sim",
    device_id: str | None = None,
    *,
    frames: int = 1,
    settings: Settings | None = None,
    sensor: str | None = None,
    config: str | None = None,
    cti: list[str] | None = None,
    timeout_s: float = 5.0,
    keep_frames: bool = True,
) -> Grabbed:
    """Open the camera, apply `settings`, acquire `frames` frames and compute their statistics; the camera is
    closed on any exit. `keep_frames` False keeps only the statistics (long grabs)."""
    if frames < 1:
        raise ConfigError("frames", frames, "must be >= 1")
    settings = settings or Settings()
    settings.check()
    options: dict[str, Any] = {"cti": list(cti or [])} if backend == "harvesters" else {}
    if backend == "sim":
        options["config"] = config
    profile = sensor_for(backend, sensor, config)
    with open_camera(backend, device_id, policy=Policy(timeout_s=timeout_s), **options) as cam:
        settings.apply(cam)
        result = Grabbed(device=dict(vars(cam.info)))
        for frame in cam.stream(frames):
            result.rows.append(frame_stats(frame, profile))
            if keep_frames:
                result.frames.append(frame)
        result.device["discarded_frames"] = cam.stats.discarded
    return result
